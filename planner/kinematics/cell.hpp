#pragma once
// The scanning cell's positioning system (thesis 6.3.2, ch. 7): axes with limits and motion profiles, the
// kinematics from axis positions to the camera-to-object pose and back, reachability of viewpoints (and the
// nearest reachable pose for those that are not), collision clearance of the scanner body, move times, and
// the travel order of a plan.
//
// Two kinematics are built in, both exact:
// - turntable_lift_tilt: the object turns on a turntable (world Z through the origin); the scanner rides a
//   radial axis (world X), a vertical lift (world Z) and a tilt about a horizontal axis parallel to world Y,
//   and a linear sweep along world Y produces the line-scan motion (camera y = world +Y, always). Closed-form
//   inverse kinematics.
// - arm_turntable: a 6-axis arm (Denavit-Hartenberg chain: closed form for the Universal Robots geometry,
//   arm_ik.hpp, else orocos-kdl's LMA) carries the scanner, the object turns on a turntable; the turntable
//   angle is chosen so the camera stands on the arm's side.
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/geometry/mesh.hpp"
#include "planner/kinematics/pose_error.hpp"

namespace scancell::planner {

enum class AxisType { rotary, linear };

struct Axis {
  std::string name;
  AxisType type = AxisType::linear;
  double min = 0.0, max = 0.0;         // rad or mm
  double max_speed = 0.0;              // rad/s or mm/s
  double max_accel = 0.0;              // rad/s² or mm/s²
  double home = 0.0;
};

enum class CellKinematics { turntable_lift_tilt, arm_turntable };

/// How an arm_turntable cell solves its arm (config `arm.ik`): closed form needs the Universal Robots geometry
/// (arm_ik.hpp); automatic takes it when the DH table has it, else the numerical solver (KDL's LMA).
enum class ArmIkSolver { automatic, closed_form, numerical };

struct Box {
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
};

struct Fixture {
  std::string name;
  bool on_table = true;  // turns with the object (the only kind supported today)
  Box box;               // in the table frame, mm
};

using JointVector = std::vector<double>;

struct CellModel {
  std::string name;
  CellKinematics kinematics = CellKinematics::turntable_lift_tilt;
  std::vector<Axis> axes;                  // the order of every JointVector
  Eigen::Isometry3d object_on_table = Eigen::Isometry3d::Identity();  // object frame in the table frame
  // The turntable's rotation axis in the world: nominally world Z through the origin; a calibration run
  // (calibration/turntable_axis) measures the real one (a point on it, mm, and its unit direction).
  Eigen::Vector3d table_axis_point_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d table_axis_direction = Eigen::Vector3d::UnitZ();
  bool nominal_table_axis() const {
    return table_axis_point_mm.head<2>().isZero(0.0) && table_axis_direction == Eigen::Vector3d::UnitZ();
  }
  Eigen::Vector3d camera_offset_mm = Eigen::Vector3d::Zero();         // turntable_lift_tilt: camera origin from the
                                                                      // tilt pivot, in the camera frame
  Box scanner_body;                        // in the camera frame, mm
  std::vector<Fixture> fixtures;
  double clearance_mm = 10.0;              // scanner body to object and fixtures
  double scan_speed_mm_s = 50.0;           // line-scan sweep speed during a scan
  PoseErrorModel pose_error;
  // arm_turntable
  std::vector<std::array<double, 4>> dh;   // per arm joint: a_mm, alpha_rad, d_mm, theta_offset_rad
  Eigen::Isometry3d arm_base = Eigen::Isometry3d::Identity();  // arm base in the world
  Eigen::Isometry3d tool = Eigen::Isometry3d::Identity();      // camera frame in the flange frame
  ArmIkSolver arm_ik = ArmIkSolver::automatic;
  bool arm_ik_closed_form() const;  // the solver automatic resolves to

  std::size_t axis_index(const std::string& name) const;  // throws ConfigError when absent
  JointVector home() const;
};

/// Reads config/cells/*.yaml; refuses missing, unknown or out-of-range keys with "file: key.path: why".
CellModel load_cell(const std::filesystem::path& file);

/// Camera-to-object pose at the given axis positions (the sweep axis at the middle of its scan).
Eigen::Isometry3d forward_kinematics(const CellModel& cell, const JointVector& q);

struct IkResult {
  bool ok = false;
  JointVector q;
  std::string why;  // when not ok: which axis or condition
};

/// The table frame in the world at turntable angle `angle_rad`: a rotation about the (calibrated) table axis.
Eigen::Isometry3d table_to_world(const CellModel& cell, double angle_rad);

/// Axis positions that put the camera at `camera_to_object` exactly (with a calibrated, tilted turntable axis:
/// the nearest pose the five axes reach, Gauss-Newton from the nominal solution; off by at most the tilt) (1e-9 mm/rad), within limits, with the
/// sweep able to travel ± scan_length/2 about its middle. `seed` guides the choice among solutions.
IkResult inverse_kinematics(const CellModel& cell, const Eigen::Isometry3d& camera_to_object, double scan_length_mm,
                            const JointVector* seed = nullptr);

/// Axis positions that put a camera tilted by `tilt_rad` (boresight in the world x-z plane, camera y along
/// world Y, as turntable_lift_tilt keeps it) `standoff_mm` from the object-frame point `p`, the turntable at
/// `table_rad`. Used for scans the cell plans for itself (rough scan, calibration).
IkResult look_at(const CellModel& cell, const Eigen::Vector3d& p, double standoff_mm, double tilt_rad, double table_rad,
                 double scan_length_mm);

/// Thesis 6.3.2: the reachable pose nearest a desired one. turntable_lift_tilt: the boresight and the
/// camera position are kept and the view is turned about its boresight until the baseline is horizontal
/// (the nearer of the two ways that the tilt range allows); arm_turntable: the pose itself when reachable.
/// nullopt (and `why`) when nothing near is reachable.
std::optional<Eigen::Isometry3d> nearest_reachable(const CellModel& cell, const Eigen::Isometry3d& desired,
                                                   double scan_length_mm, JointVector* q = nullptr,
                                                   std::string* why = nullptr);

/// Trapezoidal-profile time for one axis to travel |d| (triangular when it cannot reach full speed).
double axis_move_time_s(const Axis& axis, double distance);
/// All axes move together: the slowest axis sets the time.
double move_time_s(const CellModel& cell, const JointVector& from, const JointVector& to);
/// Duration of the line-scan sweep itself.
double scan_time_s(const CellModel& cell, double scan_length_mm);

/// Scanner-body collision checker against the object's rough model and the cell's fixtures (FCL), with the
/// clearance margin and the sweep's travel (the body inflated along camera y by the scan length).
class CollisionChecker {
 public:
  CollisionChecker(const CellModel& cell, const TriangleMesh& object_mm);
  ~CollisionChecker();
  CollisionChecker(const CollisionChecker&) = delete;
  CollisionChecker& operator=(const CollisionChecker&) = delete;
  /// True when the scanner body, swept over the scan, comes closer than the clearance to the object or a
  /// table fixture (fixtures turn with the object, so the object-relative camera pose is all it needs).
  bool collides(const Eigen::Isometry3d& camera_to_object, double scan_length_mm) const;

 private:
  struct Impl;
  Impl* impl_;
};

/// The cell's fixtures as closed box meshes in the object frame (they occlude rays like the object does).
TriangleMesh fixture_mesh(const CellModel& cell);

/// `object` with the fixtures appended (their triangles after the object's, so triangle ids below
/// object.triangles.size() are the object's).
TriangleMesh with_fixtures(const TriangleMesh& object, const CellModel& cell);

/// Execution order minimising total move time from `start`: nearest neighbour, then 2-opt (open path).
std::vector<std::size_t> travel_order(const CellModel& cell, const std::vector<JointVector>& targets,
                                      const JointVector& start);

/// Views executed in turn: the order, each view's axis targets and the summed move time (s).
struct Travel {
  std::vector<std::size_t> order;
  std::vector<JointVector> targets;  // per view (in the views' own order, not the execution order)
  double move_s = 0.0;
};

/// travel_order over `targets` (exact solutions for the camera poses `poses`, e.g. solved from home), then
/// each view re-solved from the one before it in that order (the turntable's angle modulo 2π and the arm's
/// branch nearest it) and ordered again, for as long as the total move time falls (at most `rounds` times).
/// Never slower than travel_order over `targets`; deterministic.
Travel plan_travel(const CellModel& cell, const std::vector<Eigen::Isometry3d>& poses, const std::vector<double>& scan_length_mm,
                   std::vector<JointVector> targets, const JointVector& start, int rounds = 3);

}  // namespace scancell::planner
