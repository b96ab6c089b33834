#pragma once
// The scanner side of the cell for one job (what the daemon triggers and reads profiles from): simulated
// heads (in-process, or a GigE Vision device on the loopback read through the real driver) and the real
// GenICam head. The job runner and the calibration runs see only ScanHead.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Geometry>

#include "drivers/genicam/genicam_scanner.hpp"
#include "drivers/gpio.hpp"
#include "drivers/scanner.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/kinematics/pose_error.hpp"

namespace scancell::daemon {

/// The scanner side of the cell for one job: the trigger line and the profiles it produces. A simulated head
/// also needs to know where the axes are at each trigger (`camera_at`, called just before the pulse, with the
/// axis positions read back and the pose the cell model computes from them).
class ScanHead {
 public:
  virtual ~ScanHead() = default;
  virtual drivers::DigitalOutput& trigger() = 0;
  virtual drivers::Scanner& scanner() = 0;
  virtual void camera_at(const planner::JointVector& /*q*/, const Eigen::Isometry3d& /*modelled camera_to_object*/) {}
  /// A pulse of the sweep drive's position-compare output (scanner.trigger_source: drive_compare) at the
  /// compare position `q` with the pose the cell model computes there. On a cell that output is wired to the
  /// scanner's trigger input and has already triggered it: nothing to do. A simulated head is that wire.
  virtual void compare_pulse(const planner::JointVector& /*q*/, const Eigen::Isometry3d& /*modelled camera_to_object*/) {}
  /// A positioning move has ended (the sweep of a scan is not one): a simulated positioner draws its next
  /// repeatability error here.
  virtual void moved() {}
  /// Trigger pulses fired through this head so far (acquire_view counts them): the scanner numbers its
  /// profiles by pulse from 0, so profile i answers pulse i, whatever was lost or late in between.
  std::uint64_t pulses = 0;
};

/// Builds the head for a job. `scene_mm` is what is on the table in the object frame (the job's ground-truth
/// mesh or calibration target, followed by the cell's fixtures from triangle `object_triangles` on) and
/// `placed_cell` the cell model with the object's placement; a real head ignores both.
using ScanHeadFactory = std::function<std::unique_ptr<ScanHead>(
    const planner::TriangleMesh& scene_mm, std::size_t object_triangles, const planner::CellModel& placed_cell)>;

/// What the simulated cell really is, where it differs from the daemon's models: the truth the calibration
/// runs must recover (their tests compare against it).
struct SimTruth {
  std::optional<planner::SensorModel> sensor;                         // true noise and grazing thresholds
  Eigen::Vector3d table_axis_point_mm = Eigen::Vector3d::Zero();      // true turntable axis
  Eigen::Vector3d table_axis_direction = Eigen::Vector3d::UnitZ();
  planner::PoseErrorModel pose_error;                                 // positioner repeatability, one draw per move
  std::uint64_t seed = 1;
};

/// A simulated head: the virtual scanner wired to its own trigger input. Without a truth the camera is where
/// the model says; with one, where the true kinematics (and a fresh pose-error draw per positioning move) put
/// it. With `gige`, the virtual scanner is a GigE Vision device on `gige->device` (the ArvGvFakeCamera
/// emulator, drivers/sim/sim_gige_scanner) and its profiles come through the GenICam driver, as a real
/// scanner's would; without, in-process (drivers::SimScanner).
std::unique_ptr<ScanHead> make_sim_head(const planner::SensorModel& sensor, const planner::TriangleMesh& scene_mm,
                                        std::size_t object_triangles, std::uint64_t seed,
                                        const planner::CellModel* placed_cell = nullptr, const SimTruth* truth = nullptr,
                                        const drivers::GenicamConfig* gige = nullptr);

/// A real head: a GenICam/GigE Vision line scanner whose trigger line a GPIO output drives.
std::unique_ptr<ScanHead> make_genicam_head(const planner::SensorModel& sensor, const drivers::GenicamConfig& config,
                                            const std::string& trigger_chip, unsigned trigger_offset);

}  // namespace scancell::daemon
