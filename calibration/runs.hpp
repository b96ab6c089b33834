#pragma once
// The calibration runs (thesis 1.2.1: the planner is only as good as its sensor and positioner models). Each
// run plans its own scans of a known target with the cell's kinematics, has them executed through `ScanFn`
// (the daemon binds it to the same acquisition code its jobs use: real drives, real trigger, real scanner or
// their simulators), and fits the model parameters with their uncertainties. Bad data (a scan without samples
// where the target should be, a fit that does not converge) throws scancell::DataError naming the scan; the
// caller then keeps the previous calibration.
#include <functional>
#include <string>
#include <vector>

#include "calibration/targets.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/core/sensor.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::calibration {

/// Executes one scan at axis positions `q` (sweep at the middle of its travel) over `scan_length_mm`.
using ScanFn = std::function<planner::RangeImage(const planner::JointVector& q, double scan_length_mm)>;

struct RunContext {
  planner::CellModel cell;      // the target sits at the table origin: object_on_table = identity
  planner::SensorModel sensor;  // the current model (stand-off range and field of view used to place scans)
  ScanFn scan;
  std::function<void(const planner::JointVector&)> move;  // a positioning move only (detours)
  std::function<void(const std::string&)> log = [](const std::string&) {};
};

/// A value with its 95 % confidence half-width.
struct Estimate {
  double value = 0.0, ci95 = 0.0;
};

// ---- sensor: noise coefficient and grazing thresholds ----

struct SensorRunOptions {
  int standoffs = 6;              // plate scans across [R_min, R_max]
  double plate_tilt_rad = 1.2;    // camera tilt for the noise scans (boresight 21° off the plate normal: the
                                  // radial axis cannot bring the camera nearer the table axis than 100 mm)
  double plate_aim_x_mm = 70.0;   // where on the plate the noise scans look
  double ramp_tilt_rad = 1.0;
  double scan_length_mm = 60.0;
  int t_xz_tilts = 3;             // plate scans at grazing camera tilts for t_xz
  double yield_threshold = 0.5;   // a ramp scan "measures" when this share of its rays return samples
  int t_yz_bisections = 6;
  Ramp ramp;                      // where the artefact's ramp is (sensor_target)
};

struct NoiseAtStandoff {
  double depth_mm = 0.0;    // median depth of the scan's samples
  double sigma_z_mm = 0.0;  // depth noise there (residuals normal to the fitted plane, lateral part removed)
  std::size_t samples = 0;
};

struct SensorResult {
  Estimate cz_per_mm;       // σz = C_z z²
  Estimate cx, cy;          // σx = C_x z, σy = C_y z (eq. 3.3), from oblique planes (grazing plate, ramp)
  Estimate t_xz_rad, t_yz_rad;
  std::vector<NoiseAtStandoff> noise;
  double noise_fit_rms_mm = 0.0;  // of σ_k − C_z z_k²
  int scans = 0;
  std::vector<std::pair<double, double>> yield_vs_theta_yz;  // (θ_yz rad, yield) of the ramp scans, in order
};

SensorResult run_sensor(const RunContext& ctx, const SensorRunOptions& options = {});

// ---- turntable axis ----

struct AxisRunOptions {
  int angles = 12;                 // turntable angles over a full turn
  double camera_tilt_rad = 1.15;
  double standoff_mm = 310.0;      // from the sphere's height to the camera, along the boresight
  double scan_length_mm = 150.0;
  Spheres target = axis_sphere();
};

struct AxisResult {
  Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();    // where the axis meets the table-top plane z = 0
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit, z > 0
  double direction_ci95_rad = 0.0, point_ci95_mm = 0.0;
  double circle_radius_mm = 0.0, circle_rms_mm = 0.0, sphere_rms_mm = 0.0;
  std::vector<Eigen::Vector3d> centres_world_mm;
  int scans = 0;
};

AxisResult run_turntable_axis(const RunContext& ctx, const AxisRunOptions& options = {});

// ---- positioner repeatability (thesis 7.2.4) ----

struct PositionerRunOptions {
  int poses = 4;                  // distinct measuring poses
  int repeats = 24;               // returns to each, from a different detour each time (σ to ±15 %, 95 %)
  double standoff_mm = 300.0;
  double scan_length_mm = 120.0;
  Spheres target = tripod();
  std::uint64_t seed = 1;         // detour choice
};

struct PositionerResult {
  Estimate sigma_p_mm, sigma_a_rad, sigma_t_rad;
  double sphere_rms_mm = 0.0;
  int scans = 0;
};

PositionerResult run_positioner(const RunContext& ctx, const PositionerRunOptions& options = {});

// ---- helpers shared with the tests ----

/// Axis positions that put a camera tilted by `tilt_rad` (turntable_lift_tilt convention: boresight in the
/// world x-z plane) `standoff_mm` from the target-frame point `p` with the turntable at `table_rad`;
/// DataError naming the pose when the cell cannot reach it.
planner::JointVector look_at(const planner::CellModel& cell, const Eigen::Vector3d& p, double standoff_mm,
                             double tilt_rad, double table_rad, double scan_length_mm, const std::string& what);

}  // namespace scancell::calibration
