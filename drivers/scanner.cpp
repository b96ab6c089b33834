#include "drivers/scanner.hpp"

namespace scancell::drivers {

SimScanner::SimScanner(planner::SensorModel sensor, const planner::TriangleMesh& object_mm,
                       std::function<Eigen::Isometry3d()> camera_pose, std::uint64_t seed)
    : sensor_(std::move(sensor)), scene_(object_mm), pose_(std::move(camera_pose)), seed_(seed) {}

void SimScanner::set(bool level) {
  const bool rising = level && !level_;
  level_ = level;
  if (!rising) return;
  Profile p;
  p.index = next_++;
  p.time = std::chrono::steady_clock::now();
  p.camera_to_object = pose_();
  // One profile with the laser at the camera origin: the virtual scanner over a vanishing sweep (two
  // profiles 1 nm apart), keeping the first. Same geometry, noise model and visibility as verification.
  planner::SensorModel one = sensor_;
  one.samples_y = 2;
  planner::ScanPose pose{p.camera_to_object, 1e-6};
  planner::ScanOptions o;
  o.seed = planner::mix_seed(seed_, p.index);
  const planner::RangeImage img = planner::virtual_scan(scene_, one, pose, o);
  p.samples.assign(img.samples.begin(), img.samples.begin() + img.columns);
  {
    std::lock_guard<std::mutex> lock(mu_);
    ready_.push_back(std::move(p));
  }
  cv_.notify_all();
}

Profile SimScanner::acquire(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!cv_.wait_for(lock, timeout, [&] { return !ready_.empty(); }))
    throw DriverError(DriverError::Kind::timeout, "scanner", "acquire", "no profile within " + std::to_string(timeout.count()) + " ms");
  Profile p = std::move(ready_.front());
  ready_.pop_front();
  return p;
}

}  // namespace scancell::drivers
