#pragma once
// Sensor performance model of a triangulation range camera (thesis ch. 3.4) and the model specification.
//
// Camera frame (thesis fig. 3.7): x along the laser fan, y along the mechanical sweep and the optical
// baseline, boresight = -z. Range z > 0 is the distance in front of the camera along the boresight, so a
// point at camera coordinates (x, y, -z) lies at range z. For a line-scan camera the profile that measures
// the point is taken with the laser at (0, y, 0) and the receiver at (0, y + b, 0). A random-access camera
// scans both axes optically from a fixed laser at the origin, receiver at (0, b, 0).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Core>

namespace scancell::planner {

enum class SensorKind { line_scan, random_access };

struct SensorModel {
  std::string name;
  SensorKind kind = SensorKind::line_scan;
  double fov_x_rad = 0.0;            // Φx, laser fan angle in the x-z plane
  double fov_y_rad = 0.0;            // Φy, random-access only
  double scan_length_min_mm = 0.0;   // L_y range (line-scan only)
  double scan_length_max_mm = 0.0;
  double range_min_mm = 0.0;         // R_min
  double range_max_mm = 0.0;         // R_max
  double optimal_standoff_mm = 0.0;  // R_o, usually R_min
  double baseline_mm = 0.0;          // b
  int samples_x = 0;                 // N_x
  int samples_y = 0;                 // N_y
  double noise_cx = 0.0;             // σx = C_x z (dimensionless)
  double noise_cy = 0.0;             // σy = C_y z (dimensionless)
  double noise_cz_per_mm = 0.0;      // σz = C_z z²
  double grazing_xz_rad = 0.0;       // t_xz
  double grazing_yz_rad = 0.0;       // t_yz
};

/// Model specification: what "measured" means (thesis 3.2).
struct ModelSpec {
  std::string name;
  double precision_mm = 0.0;       // required σz at most
  double density_per_mm2 = 0.0;    // required sampling density at least
  double coverage_goal = 1.0;      // fraction of the rough model's area; greedy stops once reached
};

/// Incidence geometry of one surface point seen from one sensor configuration.
struct Incidence {
  double z_mm;        // range along the boresight
  double phi_xz_rad;  // instantaneous laser scan angle
  double theta_xz_rad;
  double theta_yz_rad;
};

/// tan of ray i's angle across the fan (line scan) or the frame (random access): rays are spaced evenly
/// in angle from -Φx/2 to +Φx/2, ray i at -Φx/2 + Φx·i/(N_x - 1) (the virtual scanner's and a real
/// scanner's column geometry).
inline double ray_tan_x(const SensorModel& s, int i) {
  return std::tan(-0.5 * s.fov_x_rad + s.fov_x_rad * i / (s.samples_x - 1));
}

/// Eq. 3.3/3.4: predicted depth noise, +inf where a grazing threshold is exceeded (U_i cuts the measurement).
inline double predicted_sigma_z_mm(const SensorModel& s, const Incidence& g) {
  if (!(g.theta_yz_rad < s.grazing_yz_rad) || !(g.theta_xz_rad < s.grazing_xz_rad))
    return std::numeric_limits<double>::infinity();
  return s.noise_cz_per_mm * g.z_mm * g.z_mm / std::cos(g.theta_yz_rad);
}

/// Eq. 3.5-3.8: chord-based sampling density estimate. scan_length_mm is L_y (ignored for random access).
inline double predicted_density_per_mm2(const SensorModel& s, const Incidence& g, double scan_length_mm) {
  const double cxz = std::cos(g.theta_xz_rad), cyz = std::cos(g.theta_yz_rad);
  if (cxz <= 0.0 || cyz <= 0.0) return 0.0;
  const double slant_xz = g.z_mm / std::cos(g.phi_xz_rad);  // R_xz
  const double dx = slant_xz * s.fov_x_rad / (s.samples_x - 1) / cxz;
  double dy;
  if (s.kind == SensorKind::line_scan) {
    dy = scan_length_mm / (s.samples_y - 1) / cyz;
  } else {
    // Random access: the y axis is scanned optically like x (eq. 3.6 applied to the y-z plane).
    dy = g.z_mm * s.fov_y_rad / (s.samples_y - 1) / cyz;
  }
  return 1.0 / (dx * dx + dy * dy);
}

/// Range beyond which even a normal-incidence sample misses the precision spec.
inline double max_range_for_precision_mm(const SensorModel& s, const ModelSpec& spec) {
  return std::sqrt(spec.precision_mm / s.noise_cz_per_mm);
}

/// Result of the analytic part of the measurability test for one point and one viewpoint.
struct PointTest {
  bool in_frustum = false;
  bool facing = false;     // the surface faces both laser and receiver
  bool compliant = false;  // thresholds, precision and density meet the spec
  Incidence incidence{};
  double sigma_z_mm = 0.0;
  double density_per_mm2 = 0.0;
  double laser_y_mm = 0.0;     // camera-frame y of the laser source for this sample
  double receiver_y_mm = 0.0;  // camera-frame y of the receiver
};

/// Per-sensor constants of the hot loop, computed once per matrix build rather than per pair.
struct FrustumTerms {
  double tan_half_x = 0.0, tan_half_y = 0.0, cos_t_xz = 0.0, cos_t_yz = 0.0, dx_per_mm = 0.0;
  explicit FrustumTerms(const SensorModel& s)
      : tan_half_x(std::tan(0.5 * s.fov_x_rad)),
        tan_half_y(s.kind == SensorKind::random_access ? std::tan(0.5 * s.fov_y_rad) : 0.0),
        cos_t_xz(std::cos(s.grazing_xz_rad)),
        cos_t_yz(std::cos(s.grazing_yz_rad)),
        dx_per_mm(s.fov_x_rad / (s.samples_x - 1)) {}
};

/// Cosine of the angle between 2-D vectors (a0, a1) and (b0, b1); `fallback` when a has no length.
inline double cos_between(double a0, double a1, double b0, double b1, double fallback) {
  const double la = a0 * a0 + a1 * a1;
  if (la <= 0.0) return fallback;
  return (a0 * b0 + a1 * b1) / std::sqrt(la * (b0 * b0 + b1 * b1));
}

/// Frustum occupancy, bi-static facing and specification compliance (thesis 3.3.1) for a point p and unit
/// normal n, both in camera coordinates. Occlusion is the caller's business (it needs the scene).
/// The hot path works with cosines (no trigonometric calls); the angles are filled in only when `angles`.
inline PointTest test_point(const SensorModel& s, const FrustumTerms& f, const ModelSpec& spec, double scan_length_mm,
                            const Eigen::Vector3d& p, const Eigen::Vector3d& n, bool angles = false) {
  PointTest t;
  const double z = -p.z();
  if (!(z >= s.range_min_mm && z <= s.range_max_mm)) return t;
  if (std::abs(p.x()) > z * f.tan_half_x) return t;
  if (s.kind == SensorKind::line_scan) {
    if (std::abs(p.y()) > 0.5 * scan_length_mm) return t;
    t.laser_y_mm = p.y();
  } else {
    if (std::abs(p.y()) > z * f.tan_half_y) return t;
    t.laser_y_mm = 0.0;
  }
  t.receiver_y_mm = t.laser_y_mm + s.baseline_mm;
  t.in_frustum = true;

  // Bi-static facing: the surface must face both the laser source and the receiver.
  const double to_laser = -n.x() * p.x() + n.y() * (t.laser_y_mm - p.y()) - n.z() * p.z();
  const double to_receiver = to_laser + n.y() * s.baseline_mm;
  if (to_laser <= 0.0 || to_receiver <= 0.0) return t;
  t.facing = true;

  // Incidence of the normal projected on the x-z and y-z planes, against the laser ray direction. A normal
  // with no component in a plane has no inclination there (cos = the ray's own, or 1).
  const double cos_phi = z / std::sqrt(p.x() * p.x() + z * z);
  const double cos_xz = cos_between(n.x(), n.z(), -p.x(), z, cos_phi);
  const double cos_yz = s.kind == SensorKind::line_scan ? cos_between(n.y(), n.z(), 0.0, 1.0, 1.0)
                                                        : cos_between(n.y(), n.z(), -p.y(), z, 1.0);
  if (angles) {
    t.incidence = {z, std::acos(std::clamp(cos_phi, -1.0, 1.0)) * (p.x() < 0 ? -1.0 : 1.0),
                   std::acos(std::clamp(cos_xz, -1.0, 1.0)), std::acos(std::clamp(cos_yz, -1.0, 1.0))};
  } else {
    t.incidence.z_mm = z;
  }
  // eq. 3.4: U_i cuts the measurement at the grazing thresholds.
  if (!(cos_yz > f.cos_t_yz) || !(cos_xz > f.cos_t_xz)) return t;
  t.sigma_z_mm = s.noise_cz_per_mm * z * z / cos_yz;
  // eq. 3.6-3.8.
  const double dx = z / cos_phi * f.dx_per_mm / cos_xz;
  const double dy = (s.kind == SensorKind::line_scan ? scan_length_mm : z * s.fov_y_rad) / (s.samples_y - 1) / cos_yz;
  t.density_per_mm2 = 1.0 / (dx * dx + dy * dy);
  t.compliant = t.sigma_z_mm <= spec.precision_mm && t.density_per_mm2 >= spec.density_per_mm2;
  return t;
}

/// The deepest z (mm) at which test_point can find a point compliant, whatever its normal: eq. 3.4's σz =
/// C_z z² / cos θ_yz ≥ C_z z² bounds it by √(precision / C_z), and eq. 3.8's sample spacing (Δx ≥ z Φx / (N_x − 1),
/// Δy ≥ L / (N_y − 1) on a line scan or z Φy / (N_y − 1)) by where 1 / (Δx² + Δy²) falls under the density.
/// At most range_max_mm; 0 when no depth meets the density (a sweep too long for it). The matrix culls blocks
/// beyond it (thesis sensor and spec: 317.5 mm by precision against R_max 407).
inline double compliant_depth_max_mm(const SensorModel& s, const FrustumTerms& f, const ModelSpec& spec, double scan_length_mm) {
  double z = s.range_max_mm;
  if (s.noise_cz_per_mm > 0.0) z = std::min(z, std::sqrt(spec.precision_mm / s.noise_cz_per_mm));
  if (spec.density_per_mm2 > 0.0 && s.samples_y > 1) {
    const double spacing2 = 1.0 / spec.density_per_mm2;  // Δx² + Δy² at most
    if (s.kind == SensorKind::line_scan) {
      const double dy = scan_length_mm / (s.samples_y - 1);
      const double left = spacing2 - dy * dy;
      if (left <= 0.0) return 0.0;
      if (f.dx_per_mm > 0.0) z = std::min(z, std::sqrt(left) / f.dx_per_mm);
    } else {
      const double dy_per_mm = s.fov_y_rad / (s.samples_y - 1);
      const double per_mm2 = f.dx_per_mm * f.dx_per_mm + dy_per_mm * dy_per_mm;
      if (per_mm2 > 0.0) z = std::min(z, std::sqrt(spacing2 / per_mm2));
    }
  }
  return z;
}

/// Convenience form for tests and diagnostics: computes the sensor terms and the incidence angles.
inline PointTest test_point(const SensorModel& s, const ModelSpec& spec, double scan_length_mm, const Eigen::Vector3d& p,
                            const Eigen::Vector3d& n) {
  return test_point(s, FrustumTerms(s), spec, scan_length_mm, p, n, true);
}

}  // namespace scancell::planner
