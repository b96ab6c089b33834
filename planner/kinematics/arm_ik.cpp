#include "planner/kinematics/arm_ik.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace scancell::planner {
namespace {

constexpr double kPi = std::numbers::pi;
// A pose whose acos / asin argument lands this far outside [-1, 1] is at the edge of reach: rounding, kept.
constexpr double kEdge = 1e-9;

/// Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha) (KDL::Frame::DH, what cell.cpp's chain uses).
Eigen::Isometry3d dh_frame(const std::array<double, 4>& row, double theta) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(row[0] * std::cos(theta), row[0] * std::sin(theta), row[2]);
  t.linear() = t.linear() * Eigen::AngleAxisd(row[1], Eigen::Vector3d::UnitX()).toRotationMatrix();
  return t;
}

/// Clamps `x` into [-1, 1]; false when rounding cannot explain `x` lying outside.
bool clamp_unit(double& x) {
  if (std::abs(x) > 1.0 + kEdge) return false;
  x = std::clamp(x, -1.0, 1.0);
  return true;
}

}  // namespace

bool has_ur_geometry(const ArmDh& dh) {
  if (dh.size() != 6) return false;
  constexpr double kAlpha[6] = {kPi / 2, 0.0, 0.0, kPi / 2, -kPi / 2, 0.0};
  auto zero = [](double v) { return std::abs(v) <= 1e-9; };
  for (int k = 0; k < 6; ++k)
    if (!zero(dh[k][1] - kAlpha[k])) return false;
  return zero(dh[0][0]) && zero(dh[3][0]) && zero(dh[4][0]) && zero(dh[5][0]) && zero(dh[1][2]) && zero(dh[2][2]) &&
         !zero(dh[1][0]) && !zero(dh[2][0]) && !zero(dh[5][2]);
}

Eigen::Isometry3d dh_forward_kinematics(const ArmDh& dh, const std::array<double, 6>& q) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  for (int k = 0; k < 6; ++k) t = t * dh_frame(dh[k], q[k] + dh[k][3]);
  return t;
}

std::vector<std::array<double, 6>> ur_inverse_kinematics(const ArmDh& dh, const Eigen::Isometry3d& flange_in_base,
                                                         double q6_at_singularity) {
  const double a2 = dh[1][0], a3 = dh[2][0], d4 = dh[3][2], d6 = dh[5][2];
  const Eigen::Matrix3d& r06 = flange_in_base.linear();
  const Eigen::Vector3d p06 = flange_in_base.translation();
  const Eigen::Vector3d p05 = p06 - d6 * r06.col(2);
  std::vector<std::array<double, 6>> out;
  // theta1: the wrist centre stands d4 along the shoulder axis z1 = (sin t1, -cos t1, 0).
  const double rho = std::hypot(p05.x(), p05.y());
  double s = rho > 0.0 ? d4 / rho : 2.0;
  if (!clamp_unit(s)) return out;
  const double psi = std::atan2(p05.y(), p05.x());
  for (const double t1 : {psi + std::asin(s), psi + kPi - std::asin(s)}) {
    const Eigen::Vector3d z1(std::sin(t1), -std::cos(t1), 0.0);
    // theta5: the flange stands d4 + d6 cos t5 along z1.
    double c5 = (p06.dot(z1) - d4) / d6;
    if (!clamp_unit(c5)) continue;
    for (const double sign5 : {1.0, -1.0}) {
      const double t5 = sign5 * std::acos(c5);
      if (sign5 < 0.0 && t5 == 0.0) continue;  // one wrist branch at the singularity
      // theta6: z1 seen from the flange is (sin t5 cos t6, -sin t5 sin t6, cos t5).
      const double s5 = std::sin(t5);
      const double t6 = std::abs(s5) < 1e-12 ? q6_at_singularity + dh[5][3]
                                             : std::atan2(-r06.col(1).dot(z1) / s5, r06.col(0).dot(z1) / s5);
      // The planar chain: frame 4 in frame 1.
      const Eigen::Isometry3d t14 = dh_frame(dh[0], t1).inverse() * flange_in_base * dh_frame(dh[5], t6).inverse() *
                                    dh_frame(dh[4], t5).inverse();
      const double px = t14.translation().x(), py = t14.translation().y();
      double c3 = (px * px + py * py - a2 * a2 - a3 * a3) / (2.0 * a2 * a3);
      if (!clamp_unit(c3)) continue;
      // R14 = Rz(t2 + t3 + t4) Rx(alpha4), whichever the elbow.
      const Eigen::Matrix3d r = t14.linear() * Eigen::AngleAxisd(-dh[3][1], Eigen::Vector3d::UnitX()).toRotationMatrix();
      const double t234 = std::atan2(r(1, 0), r(0, 0));
      for (const double sign3 : {1.0, -1.0}) {
        const double t3 = sign3 * std::acos(c3);
        if (sign3 < 0.0 && t3 == 0.0) continue;  // one elbow branch, stretched out
        const double t2 = std::atan2(py, px) - std::atan2(a3 * std::sin(t3), a2 + a3 * std::cos(t3));
        const double t4 = t234 - t2 - t3;
        const double theta[6] = {t1, t2, t3, t4, t5, t6};
        std::array<double, 6> q;
        for (int k = 0; k < 6; ++k) q[k] = std::remainder(theta[k] - dh[k][3], 2.0 * kPi);
        out.push_back(q);
      }
    }
  }
  return out;
}

}  // namespace scancell::planner
