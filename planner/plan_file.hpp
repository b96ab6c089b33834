#pragma once
// Reading a plan file back (docs/plan-format.md) for the verifier, the daemon and tools: only what executing
// the plan needs, every field checked, errors naming the file and the JSON path.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "planner/sensor.hpp"
#include "planner/viewpoint.hpp"
#include "planner/virtual_scanner.hpp"

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
};

/// Throws DataError (structure, values) or ConfigError (the embedded sensor / spec) naming file and path.
PlanFile load_plan_file(const std::filesystem::path& path);

}  // namespace scancell::planner
