#include "drivers/sim/sim_scanner.hpp"

namespace scancell::drivers {

SimScanner::SimScanner(planner::SensorModel sensor, const planner::TriangleMesh& object_mm,
                       std::function<Eigen::Isometry3d()> camera_pose, std::uint64_t seed, std::size_t object_triangles)
    : sensor_(std::move(sensor)), scene_(object_mm), pose_(std::move(camera_pose)), seed_(seed),
      object_triangles_(object_triangles) {
  worker_ = std::thread([this] { measure_loop(); });
}

void SimScanner::set(bool level) {
  const bool rising = level && !level_;
  level_ = level;
  if (!rising) return;
  // Capture the pose now, measure on the scanner's own thread: the trigger line returns at once, as a real
  // scanner's input does, so position-compare triggering is not slowed by the ray casting.
  Profile p;
  p.index = next_++;
  p.time = std::chrono::steady_clock::now();
  p.camera_to_object = pose_();
  {
    std::lock_guard<std::mutex> lock(mu_);
    pending_.push_back(std::move(p));
  }
  cv_.notify_all();
}

void SimScanner::measure_loop() {
  while (true) {
    Profile p;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return stop_ || !pending_.empty(); });
      if (pending_.empty()) return;
      p = std::move(pending_.front());
      pending_.pop_front();
    }
    // One profile with the laser at the camera origin: the virtual scanner over a vanishing sweep (two
    // profiles 1 nm apart), keeping the first. Same geometry, noise model and visibility as verification.
    planner::SensorModel one = sensor_;
    one.samples_y = 2;
    planner::ScanPose pose{p.camera_to_object, 1e-6};
    planner::ScanOptions o;
    o.seed = planner::mix_seed(seed_, p.index);
    o.object_triangles = object_triangles_;
    const planner::RangeImage img = planner::virtual_scan(scene_, one, pose, o);
    p.samples.assign(img.samples.begin(), img.samples.begin() + img.columns);
    p.truth.assign(img.truth.begin(), img.truth.begin() + img.columns);
    {
      std::lock_guard<std::mutex> lock(mu_);
      ready_.push_back(std::move(p));
    }
    cv_.notify_all();
  }
}

SimScanner::~SimScanner() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
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
