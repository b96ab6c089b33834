#pragma once
// Simulated line scanner (beside the Scanner interface, never inside it): every rising edge of its trigger
// input captures one profile by ray-casting a ground-truth mesh with the virtual scanner (the verifier's
// code, calibrated noise) at the pose the simulated axes report at that instant.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

#include <Eigen/Geometry>

#include "drivers/gpio.hpp"
#include "drivers/scanner.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::drivers {

/// Simulated line scanner wired to the trigger line: every rising edge captures one profile at the pose
/// `camera_pose()` returns at that instant (the cell's kinematics at the simulated axes' positions).
class SimScanner : public Scanner, public DigitalOutput {
 public:
  /// `scene_mm`: the object in its frame, optionally followed by cell fixtures (the plate) from triangle
  /// `object_triangles` on, which block rays but give no samples (0: all of it is the object).
  SimScanner(planner::SensorModel sensor, const planner::TriangleMesh& scene_mm,
             std::function<Eigen::Isometry3d()> camera_pose, std::uint64_t seed = 1, std::size_t object_triangles = 0);
  ~SimScanner() override;
  SimScanner(const SimScanner&) = delete;
  SimScanner& operator=(const SimScanner&) = delete;
  void set(bool level) override;  // the trigger input
  Profile acquire(std::chrono::milliseconds timeout) override;

 private:
  planner::SensorModel sensor_;
  planner::OcclusionScene scene_;
  std::function<Eigen::Isometry3d()> pose_;
  std::uint64_t seed_;
  std::size_t object_triangles_;
  bool level_ = false;
  std::uint64_t next_ = 0;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Profile> pending_, ready_;  // triggered, not yet measured; measured, not yet acquired
  bool stop_ = false;
  void measure_loop();
  std::thread worker_;
};

}  // namespace scancell::drivers
