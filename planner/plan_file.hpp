#pragma once
// Reading a plan file back (docs/plan-format.md) for the verifier, the daemon and tools: only what executing
// the plan needs, every field checked, errors naming the file and the JSON path.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "planner/geometry/mesh.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

struct PlanFile {
  std::string path;
  std::string mesh_path;                                        // object.mesh as given to the planner
  Eigen::Matrix4d object_transform = Eigen::Matrix4d::Identity();  // mesh -> plan (object) coordinates
  SensorModel sensor;
  ModelSpec spec;
  std::vector<ScanPose> views;                    // selection order
  std::vector<Viewpoint> viewpoints;              // the same views as viewpoints (axis, twist, scan length)
  std::vector<double> estimated_cumulative;       // the planner's cumulative estimated measurability per view
  std::string cell;                               // the cell planned for, empty if none
  Eigen::Matrix4d object_on_table = Eigen::Matrix4d::Identity();  // object frame in the table frame
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> table_fixtures;  // boxes (min, max) in the table frame
  /// The fixtures as a mesh in the object frame (empty without a cell).
  TriangleMesh fixtures_in_object_frame() const;
};

/// Throws DataError (structure, values) or ConfigError (the embedded sensor / spec) naming file and path.
PlanFile load_plan_file(const std::filesystem::path& path);

}  // namespace scancell::planner
