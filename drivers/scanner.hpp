#pragma once
// The line scanner: one profile per trigger pulse. The simulated one (drivers/sim/sim_scanner.hpp)
// ray-casts a ground-truth mesh at the pose the axes are at when the pulse arrives.
#include <chrono>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/scan/range_image.hpp"

namespace scancell::drivers {

struct Profile {
  std::uint64_t index = 0;                            // trigger pulse number since start
  std::chrono::steady_clock::time_point time;
  Eigen::Isometry3d camera_to_object = Eigen::Isometry3d::Identity();  // where the camera was
  std::vector<planner::RangeSample> samples;          // N_x, laser at the camera origin; invalid where no return
  std::vector<planner::SampleTruth> truth;            // simulated scanners only, parallel to samples; else empty
  bool lost = false;  // triggered but never delivered (lost or incomplete frame): no samples, order kept
};

class Scanner {
 public:
  virtual ~Scanner() = default;
  /// The next profile, in trigger order; DriverError(timeout) when none arrives in time.
  virtual Profile acquire(std::chrono::milliseconds timeout) = 0;
};

}  // namespace scancell::drivers
