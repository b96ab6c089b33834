#pragma once
// What a client's submit asks for (daemon/control's `submit`), stored with the job as JSON and checked before
// the job is accepted: every file it names is loaded once, so a job never starts on a mesh or config that
// would be refused later.
#include <atomic>
#include <cstddef>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "daemon/job_limits.hpp"
#include "planner/geometry/mesh.hpp"

namespace scancell::daemon {

/// What a submit request asks for, validated (files loaded) before the job is accepted.
struct JobRequest {
  std::string mesh;                    // rough model of the object (absolute path)
  double fit_mm = 0.0;                 // scale so the longest side is this (0: the mesh is in mm)
  std::string spec, settings;          // optional overrides (absolute paths)
  std::string truth;                   // simulation: the object actually on the table (default: mesh)
  std::optional<std::size_t> rough_vertices;
  /// Instead of a mesh: the object's approximate size (x, y, z mm), standing centred on the turntable. The
  /// job then starts with a rough scan and plans from the rough model it fuses.
  std::optional<Eigen::Vector3d> bbox_mm;
  /// How the object rests on the plate: "auto" (plan its stable resting poses, keep the best; the operator
  /// places it as the result says), "as_given", or empty for the settings' placement.mode.
  std::string placement;
  /// Setups the job may use (issue 20): after the first, when enough is left unmeasured, the job waits for
  /// the operator to turn the part over as it says (awaiting_operator) and measures the rest. Empty: the
  /// daemon's jobs.max_setups. Mesh jobs only.
  std::optional<int> setups;
  nlohmann::json to_json() const;
  static JobRequest from_json(const nlohmann::json& j);
};

/// Loads and checks everything a request names; throws scancell::MeshError/ConfigError naming the file. A
/// non-zero `cancel` stops a mesh read at once (MeshError): the daemon stopping does not wait for it.
void validate_request(const JobRequest& r, const std::atomic<int>* cancel = nullptr);

/// The object's mesh as a job uses it: loaded (30 s at most; `cancel` stops the read) and, with `fit_mm` > 0,
/// scaled so its longest side is that many mm.
planner::TriangleMesh load_object(const std::string& path, double fit_mm, const std::atomic<int>* cancel = nullptr);

}  // namespace scancell::daemon
