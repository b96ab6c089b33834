#pragma once
// Closed-form inverse kinematics of six-axis arms with the Universal Robots geometry: joints 2-4 parallel,
// an offset wrist (standard Denavit-Hartenberg a1 = a4 = a5 = a6 = 0, d2 = d3 = 0, alpha = π/2, 0, 0, π/2,
// -π/2, 0). The cell's shipped arm (config/cells/arm-turntable.yaml) is one. Every branch of the solution
// (shoulder left/right, wrist up/down, elbow up/down: up to 8) comes out in a few microseconds, where a
// numerical solver (KDL's LMA) from a handful of seeds took milliseconds and could miss a branch its seeds did
// not lead to. Derivation: the wrist centre p05 = p06 - d6 z6 lies d4 off the shoulder's plane (theta1); the
// flange's height along the shoulder axis z1 is d4 + d6 cos(theta5); z1 seen from the flange gives theta6; the
// remaining planar 3R chain (a2, a3) gives theta2, theta3, and its summed angle theta4.
#include <array>
#include <vector>

#include <Eigen/Geometry>

namespace scancell::planner {

/// Per arm joint: a_mm, alpha_rad, d_mm, theta_offset_rad (the joint angle is theta - theta_offset).
using ArmDh = std::vector<std::array<double, 4>>;

/// True when `dh` has the Universal Robots geometry above (to 1e-9 mm / rad).
bool has_ur_geometry(const ArmDh& dh);

/// Every joint solution (joint angles, theta offsets removed; not wrapped into any limits) that puts the flange
/// at `flange_in_base` (the last DH frame in the first joint's base frame, mm). At a wrist singularity
/// (sin theta5 = 0), where only theta4 + theta6 is determined, theta6 is taken as `q6_at_singularity`. Solutions
/// are exact up to rounding; acos near ±1 may leave ~1e-8 rad that a caller needing more polishes away.
/// Empty when the pose is out of reach. Requires has_ur_geometry(dh).
std::vector<std::array<double, 6>> ur_inverse_kinematics(const ArmDh& dh, const Eigen::Isometry3d& flange_in_base,
                                                         double q6_at_singularity = 0.0);

/// The flange in the arm's base frame at joint angles `q` (the product of the DH frames).
Eigen::Isometry3d dh_forward_kinematics(const ArmDh& dh, const std::array<double, 6>& q);

}  // namespace scancell::planner
