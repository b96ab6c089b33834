#include "daemon/scan_heads.hpp"

#include <mutex>

#include "drivers/sim/sim_gige_scanner.hpp"
#include "drivers/sim/sim_scanner.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::daemon {
namespace {

namespace sp = scancell::planner;
namespace dr = scancell::drivers;

/// The camera pose of a simulated cell at each trigger: the modelled pose, or with a truth the true
/// kinematics and the last positioning move's pose-error draw (the sweep carries the camera rigidly).
class SimPose {
 public:
  SimPose(const sp::CellModel* placed, const SimTruth* truth) {
    if (truth && placed) {
      truth_ = *truth;
      cell_ = *placed;
      cell_->table_axis_point_mm = truth->table_axis_point_mm;
      cell_->table_axis_direction = truth->table_axis_direction.normalized();
    }
  }
  void moved() {
    std::lock_guard<std::mutex> lock(mu_);
    ++moves_;
  }
  void camera_at(const sp::JointVector& q, const Eigen::Isometry3d& modelled) {
    Eigen::Isometry3d p = modelled;
    std::lock_guard<std::mutex> lock(mu_);
    if (cell_) {
      sp::ScanPose sp_pose{sp::forward_kinematics(*cell_, q), 0.0};
      p = sp::sample_pose_error(sp_pose, truth_.pose_error, sp::mix_seed(truth_.seed, moves_, 7)).camera_to_object;
    }
    pose_ = p;
  }
  Eigen::Isometry3d now() {
    std::lock_guard<std::mutex> lock(mu_);
    return pose_;
  }

 private:
  std::mutex mu_;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();
  std::optional<sp::CellModel> cell_;
  SimTruth truth_;
  std::uint64_t moves_ = 0;
};

/// The GenICam driver's profiles with the simulated device's truth joined by trigger counter: the wire
/// carries ranges only, the simulator knows where each ray hit (SimGigeScanner::take_truth).
class TruthJoined : public dr::Scanner {
 public:
  TruthJoined(dr::Scanner& wire, dr::SimGigeScanner& device) : wire_(wire), device_(device) {}
  dr::Profile acquire(std::chrono::milliseconds timeout) override {
    dr::Profile p = wire_.acquire(timeout);
    if (!p.lost) p.truth = device_.take_truth(p.index);
    if (p.truth.size() != p.samples.size()) p.truth.clear();  // unknown: the job says its checks were not run
    return p;
  }

 private:
  dr::Scanner& wire_;
  dr::SimGigeScanner& device_;
};

class SimHead : public ScanHead {
 public:
  SimHead(const sp::SensorModel& sensor, const sp::TriangleMesh& scene, std::size_t object_triangles, std::uint64_t seed,
          const sp::CellModel* placed, const SimTruth* truth, const dr::GenicamConfig* gige)
      : pose_(placed, truth) {
    const sp::SensorModel& real = truth && truth->sensor ? *truth->sensor : sensor;
    auto now = [this] { return pose_.now(); };
    if (gige) {
      dr::SimGigeOptions o;
      o.interface = gige->device;
      o.seed = seed;
      o.object_triangles = object_triangles;
      device_ = std::make_unique<dr::SimGigeScanner>(real, scene, now, o);
      // The driver reads the device as it would a real scanner: with the daemon's sensor model.
      driver_ = std::make_unique<dr::GenicamScanner>(sensor, *gige);
      joined_ = std::make_unique<TruthJoined>(*driver_, *device_);
      trigger_ = device_.get();
      scanner_ = joined_.get();
    } else {
      sim_ = std::make_unique<dr::SimScanner>(real, scene, now, seed, object_triangles);
      trigger_ = sim_.get();
      scanner_ = sim_.get();
    }
  }
  dr::DigitalOutput& trigger() override { return *trigger_; }
  dr::Scanner& scanner() override { return *scanner_; }
  void moved() override { pose_.moved(); }
  void camera_at(const sp::JointVector& q, const Eigen::Isometry3d& modelled) override { pose_.camera_at(q, modelled); }
  // The wire from the drive's compare output to the scanner's trigger input: the scanner measures at the
  // compare position, whenever the daemon hears of the pulse.
  void compare_pulse(const sp::JointVector& q, const Eigen::Isometry3d& modelled) override {
    pose_.camera_at(q, modelled);
    trigger_->set(true);
    trigger_->set(false);
  }

 private:
  SimPose pose_;
  std::unique_ptr<dr::SimScanner> sim_;
  std::unique_ptr<dr::SimGigeScanner> device_;  // declared before the driver: the driver closes first
  std::unique_ptr<dr::GenicamScanner> driver_;
  std::unique_ptr<TruthJoined> joined_;
  dr::DigitalOutput* trigger_ = nullptr;
  dr::Scanner* scanner_ = nullptr;
};

class GenicamHead : public ScanHead {
 public:
  // `chip` sim: no line at all (scanner.trigger_source drive_compare, where the drive's compare output is
  // what triggers the scanner; the loader refuses it otherwise).
  GenicamHead(const sp::SensorModel& sensor, const dr::GenicamConfig& config, const std::string& chip, unsigned offset)
      : trigger_(chip == "sim" ? std::unique_ptr<dr::DigitalOutput>(std::make_unique<dr::SimOutput>())
                               : std::make_unique<dr::GpiodOutput>(chip, offset, false)),
        scanner_(sensor, config) {}
  dr::DigitalOutput& trigger() override { return *trigger_; }
  dr::Scanner& scanner() override { return scanner_; }

 private:
  std::unique_ptr<dr::DigitalOutput> trigger_;
  dr::GenicamScanner scanner_;
};

}  // namespace

std::unique_ptr<ScanHead> make_sim_head(const sp::SensorModel& sensor, const sp::TriangleMesh& scene,
                                        std::size_t object_triangles, std::uint64_t seed, const sp::CellModel* placed,
                                        const SimTruth* truth, const dr::GenicamConfig* gige) {
  return std::make_unique<SimHead>(sensor, scene, object_triangles, seed, placed, truth, gige);
}

std::unique_ptr<ScanHead> make_genicam_head(const sp::SensorModel& sensor, const dr::GenicamConfig& config,
                                            const std::string& trigger_chip, unsigned trigger_offset) {
  return std::make_unique<GenicamHead>(sensor, config, trigger_chip, trigger_offset);
}

}  // namespace scancell::daemon
