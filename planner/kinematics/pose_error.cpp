#include "planner/kinematics/pose_error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <sstream>

namespace scancell::planner {

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::numbers::sqrt2); }

PoseErrorEffects pose_error_effects(const SensorModel& s, const PoseErrorModel& e, double fd, double dof_risk) {
  using std::numbers::pi;
  PoseErrorEffects r;
  r.fd = fd;
  r.dof_risk = dof_risk;
  const double ro = s.optimal_standoff_mm;
  const double px = s.fov_x_rad;            // Φx
  const double phi2 = 0.5 * px;             // Φ2 = Φx/2
  const double t = std::tan(phi2);          // TΦ2
  const double np = e.sigma_p_mm / ro;      // σ_p / R_o
  const double np2 = np * np;
  const double sa = e.sigma_a_rad, st = e.sigma_t_rad;

  // Table 7.3 (C.?): position, axis, twist effects on relative precision and density.
  r.precision_position = {1.0 + np2 / (3.0 * fd * fd), std::sqrt(4.0 * np2 / (3.0 * fd * fd))};
  r.precision_axis = {1.0 - 0.75 * sa * sa, 0.0};
  r.precision_twist = {1.0, 0.0};
  r.density_position = {1.0 + np2 / (3.0 * fd * fd), std::sqrt(2.0 * np2 / (3.0 * fd * fd))};
  r.density_axis = {1.0 - 0.25 * sa * sa, 0.0};
  r.density_twist = {1.0, 0.0};

  // Table 7.4 (C.78/79, C.145/146 and the twist pair): relative targeted footprint.
  {
    const double k = px * t + px + 2.0 * t;
    const double mu = 1.0 - k / (2.0 * fd * px * t) * std::sqrt(2.0 / (3.0 * pi)) * np +
                      (t + 1.0) / (3.0 * pi * fd * fd * px * t) * np2;
    const double var = k * k / (4.0 * fd * fd * px * px * t * t) * ((pi - 2.0) / (3.0 * pi)) * np2;
    r.footprint_position = {mu, std::sqrt(var)};
  }
  {
    const double mu = 1.0 - (px + 2.0 * t) / (pi * t * px) * std::sqrt(2.0 / pi) * sa + sa * sa / (2.0 * pi * t * px);
    const double var = sa * sa / (8.0 * pi * pi * pi * t * t * px * px) *
                       ((4.0 * t * t + px * px) * (pi * pi * pi - 16.0) + 8.0 * t * px * (pi * pi - 8.0));
    r.footprint_axis = {mu, std::sqrt(std::max(0.0, var))};
  }
  {
    const double k = px * px + 4.0 * t * t;
    const double mu = 1.0 - k / (8.0 * px * t) * std::sqrt(2.0 / pi) * st + 0.5 * st * st;
    const double var = k * k / (64.0 * px * px * t * t) * ((pi - 2.0) / pi) * st * st;
    r.footprint_twist = {mu, std::sqrt(var)};
  }

  // Table 7.5 (C.82, C.150): depth-of-field erosion.
  r.dof_erosion_position = np > 0.0 ? 1.0 - normal_cdf(std::sqrt(3.0) * (fd - 1.0) / np) : 0.0;
  r.dof_erosion_axis = sa > 0.0 ? 1.0 - normal_cdf((fd - 1.0) / (fd * phi2 * sa)) : 0.0;

  // Smallest f_d with both probabilities ≤ dof_risk: invert the two expressions at z = Φ⁻¹(1 − risk).
  double z = 0.0;
  for (double lo = 0.0, hi = 40.0; hi - lo > 1e-12;) {  // bisection on Φ(z) = 1 − risk
    z = 0.5 * (lo + hi);
    (1.0 - normal_cdf(z) > dof_risk ? lo : hi) = z;
  }
  const double fd_position = 1.0 + z * np / std::sqrt(3.0);
  const double a = z * phi2 * sa;  // (f_d − 1)/(f_d Φ2 σ_a) ≥ z  <=>  f_d ≥ 1/(1 − z Φ2 σ_a)
  const double fd_axis = a < 1.0 ? 1.0 / (1.0 - a) : std::numeric_limits<double>::infinity();
  r.suggested_fd = std::max({1.0, fd_position, fd_axis});
  return r;
}

Countermeasures countermeasures_for(const SensorModel& s, const PoseErrorModel& e, double fd) {
  const PoseErrorEffects x = pose_error_effects(s, e, fd);
  Countermeasures c;
  // Footprint kept at two sigma: the product of the three error kinds' low ends.
  const double keep = std::max(0.0, x.footprint_position.mean - 2.0 * x.footprint_position.sd) *
                      std::max(0.0, x.footprint_axis.mean - 2.0 * x.footprint_axis.sd) *
                      std::max(0.0, x.footprint_twist.mean - 2.0 * x.footprint_twist.sd);
  // TF scales with width × length; shrinking both by d keeps (1 − d)².
  c.frustum_detune = std::clamp(1.0 - std::sqrt(keep), 0.0, 0.5);
  const double p_hi = std::max({x.precision_position.mean + 2.0 * x.precision_position.sd, x.precision_axis.mean, 1.0});
  const double d_lo = std::min({x.density_position.mean - 2.0 * x.density_position.sd, x.density_axis.mean, 1.0});
  c.compliance_buffer = std::max(p_hi - 1.0, 1.0 / std::max(d_lo, 1e-6) - 1.0);
  c.dof_margin_mm = 3.0 * e.sigma_p_mm + fd * s.optimal_standoff_mm * std::tan(0.5 * s.fov_x_rad) * std::sin(2.0 * e.sigma_a_rad);
  c.visibility_margin_mm = 2.0 * e.sigma_p_mm;
  return c;
}

ScanPose sample_pose_error(const ScanPose& pose, const PoseErrorModel& e, std::uint64_t seed) {
  if (e.zero()) return pose;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(-std::numbers::pi, std::numbers::pi);
  // Position: Gaussian magnitude, uniformly distributed direction.
  Eigen::Vector3d dir(g(rng), g(rng), g(rng));
  dir = dir.norm() > 0.0 ? dir.normalized() : Eigen::Vector3d::UnitX();
  const double mag = e.sigma_p_mm * g(rng);
  // Axis: rotation by α = N(0, σ_a) about an axis in the camera x-y plane at angle β ~ U(−π, π).
  const double alpha = e.sigma_a_rad * g(rng), beta = u(rng);
  // Twist: N(0, σ_t) about the boresight.
  const double twist = e.sigma_t_rad * g(rng);
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(alpha, Eigen::Vector3d(std::cos(beta), std::sin(beta), 0.0)) *
                             Eigen::AngleAxisd(twist, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  ScanPose out = pose;
  out.camera_to_object.linear() = pose.camera_to_object.linear() * r;
  out.camera_to_object.translation() = pose.camera_to_object.translation() + mag * dir;
  return out;
}

std::string pose_error_report(const SensorModel& s, const PoseErrorModel& e, double fd) {
  const PoseErrorEffects x = pose_error_effects(s, e, fd);
  const Countermeasures c = countermeasures_for(s, e, fd);
  std::ostringstream os;
  char b[256];
  std::snprintf(b, sizeof b,
                "sensor %s: Φx %.4f rad, R_o %.1f mm; f_d %.4f; σ_p %.4f mm, σ_a %.5f rad, σ_t %.5f rad\n",
                s.name.c_str(), s.fov_x_rad, s.optimal_standoff_mm, fd, e.sigma_p_mm, e.sigma_a_rad, e.sigma_t_rad);
  os << b << "single-view effects, optimal scanning configuration (thesis tables 7.3-7.5), mean ± sd:\n";
  os << "                              position            axis                twist\n";
  auto row = [&](const char* name, const Moments& p, const Moments& a, const Moments& t) {
    std::snprintf(b, sizeof b, "  %-26s  %.6f ± %.6f  %.6f ± %.6f  %.6f ± %.6f\n", name, p.mean, p.sd, a.mean, a.sd, t.mean, t.sd);
    os << b;
  };
  row("relative precision P_rel", x.precision_position, x.precision_axis, x.precision_twist);
  row("relative density D_rel", x.density_position, x.density_axis, x.density_twist);
  row("relative footprint TF_rel", x.footprint_position, x.footprint_axis, x.footprint_twist);
  std::snprintf(b, sizeof b, "  %-26s  %.3e            %.3e            0\n", "P(depth-of-field erosion)", x.dof_erosion_position,
                x.dof_erosion_axis);
  os << b;
  std::snprintf(b, sizeof b, "suggested f_d (erosion probability <= %.0e): %.4f\n", x.dof_risk, x.suggested_fd);
  os << b;
  std::snprintf(b, sizeof b,
                "countermeasures (7.4.7): frustum_detune %.4f, compliance_buffer %.4f, dof_margin_mm %.3f, "
                "visibility_margin_mm %.3f\n",
                c.frustum_detune, c.compliance_buffer, c.dof_margin_mm, c.visibility_margin_mm);
  os << b;
  return os.str();
}

}  // namespace scancell::planner
