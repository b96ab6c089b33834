#pragma once
// Sensor performance model of a triangulation range camera (thesis ch. 3.4) and the model specification.
//
// Camera frame (thesis fig. 3.7): x along the laser fan, y along the mechanical sweep and the optical
// baseline, boresight = -z. Range z > 0 is the distance in front of the camera along the boresight, so a
// point at camera coordinates (x, y, -z) lies at range z. For a line-scan camera the profile that measures
// the point is taken with the laser at (0, y, 0) and the receiver at (0, y + b, 0). A random-access camera
// scans both axes optically from a fixed laser at the origin, receiver at (0, b, 0).
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

/// Frustum occupancy, bi-static facing and specification compliance (thesis 3.3.1) for a point p and unit
/// normal n, both in camera coordinates. Occlusion is the caller's business (it needs the scene).
inline PointTest test_point(const SensorModel& s, const ModelSpec& spec, double scan_length_mm,
                            const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  PointTest t;
  const double z = -p.z();
  if (!(z >= s.range_min_mm && z <= s.range_max_mm)) return t;
  const double half_x = 0.5 * s.fov_x_rad;
  if (std::abs(p.x()) > z * std::tan(half_x)) return t;
  if (s.kind == SensorKind::line_scan) {
    if (std::abs(p.y()) > 0.5 * scan_length_mm) return t;
    t.laser_y_mm = p.y();
  } else {
    if (std::abs(p.y()) > z * std::tan(0.5 * s.fov_y_rad)) return t;
    t.laser_y_mm = 0.0;
  }
  t.receiver_y_mm = t.laser_y_mm + s.baseline_mm;
  t.in_frustum = true;

  // Bi-static facing: the surface must face both the laser source and the receiver.
  const Eigen::Vector3d to_laser(-p.x(), t.laser_y_mm - p.y(), -p.z());
  const Eigen::Vector3d to_receiver(-p.x(), t.receiver_y_mm - p.y(), -p.z());
  if (n.dot(to_laser) <= 0.0 || n.dot(to_receiver) <= 0.0) return t;
  t.facing = true;

  // Incidence of the normal projected on the x-z and y-z planes, against the laser ray direction.
  Incidence& g = t.incidence;
  g.z_mm = z;
  g.phi_xz_rad = std::atan2(p.x(), z);
  g.theta_xz_rad = std::abs(std::atan2(n.x(), n.z()) - std::atan2(-p.x(), z));
  const double laser_dir_yz = (s.kind == SensorKind::line_scan) ? 0.0 : std::atan2(-p.y(), z);
  g.theta_yz_rad = std::abs(std::atan2(n.y(), n.z()) - laser_dir_yz);

  t.sigma_z_mm = predicted_sigma_z_mm(s, g);
  if (!std::isfinite(t.sigma_z_mm)) return t;
  t.density_per_mm2 = predicted_density_per_mm2(s, g, scan_length_mm);
  t.compliant = t.sigma_z_mm <= spec.precision_mm && t.density_per_mm2 >= spec.density_per_mm2;
  return t;
}

}  // namespace scancell::planner
