#include "calibration/runs.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <sstream>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "calibration/fit.hpp"
#include "common/errors.hpp"

namespace scancell::calibration {

namespace sp = scancell::planner;
using scancell::DataError;

namespace {

std::string deg(double rad) {
  std::ostringstream os;
  os.precision(3);
  os << std::fixed << rad * 180.0 / std::numbers::pi << "°";
  return os.str();
}

/// The scan's valid samples: view-frame (camera_mm) and target-frame (object_mm) points with their pixel.
struct Samples {
  std::vector<Eigen::Vector3d> view, target;
  std::vector<std::pair<int, int>> pixel;
};

Samples samples_of(const sp::RangeImage& img) {
  Samples s;
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const auto& x = img.at(i, j);
      if (!x.valid()) continue;
      s.view.push_back(x.camera_mm.cast<double>());
      s.target.push_back(x.object_mm.cast<double>());
      s.pixel.emplace_back(i, j);
    }
  return s;
}

/// View-frame samples whose target-frame position passes `keep` (on the plate, on the ramp's face).
template <class Keep>
std::vector<Eigen::Vector3d> view_points_where(const sp::RangeImage& img, Keep keep) {
  const Samples smp = samples_of(img);
  std::vector<Eigen::Vector3d> out;
  for (std::size_t i = 0; i < smp.view.size(); ++i)
    if (keep(smp.target[i])) out.push_back(smp.view[i]);
  return out;
}

double tan_x(const sp::SensorModel& s, int i) { return sp::ray_tan_x(s, i); }

/// Incidence angles of the virtual scanner (planner/sim/virtual_scanner.cpp) for a plane normal `n` in the view
/// frame (facing the camera) and laser ray i: θ_xz against the ray back to the laser, θ_yz in the laser plane.
double theta_xz(const Eigen::Vector3d& n, double tx) {
  const Eigen::Vector2d a(n.x(), n.z()), b(-tx, 1.0);
  return std::acos(std::clamp(a.dot(b) / (a.norm() * b.norm()), -1.0, 1.0));
}
double theta_yz(const Eigen::Vector3d& n) { return std::atan2(std::abs(n.y()), n.z()); }

/// Per-ray outcome on a known plane: for every pixel whose ray would hit the plane inside `inside` (target
/// frame), within the sensor's range and facing laser and receiver, its θ_xz and whether a sample came back.
struct RayOutcome {
  double theta_xz;
  bool returned;
};

template <class Inside>
std::vector<RayOutcome> rays_on_plane(const sp::RangeImage& img, const sp::SensorModel& s, const Eigen::Vector3d& n_view,
                                      const Eigen::Vector3d& p_view, Inside inside) {
  std::vector<RayOutcome> out;
  for (int j = 0; j < img.rows; ++j) {
    // A profile the sweep never fired returned nothing because it was not taken: not evidence of a ray that
    // found no surface (under load the polled sweep loses profiles, and t_yz came out 16° low).
    if (!img.acquired_rows.empty() && !img.acquired_rows[static_cast<std::size_t>(j)]) continue;
    const double y = -0.5 * img.pose.scan_length_mm + img.pose.scan_length_mm * j / (img.rows - 1);
    const Eigen::Vector3d laser(0.0, y, 0.0), receiver(0.0, y + s.baseline_mm, 0.0);
    for (int i = 0; i < img.columns; ++i) {
      const double tx = tan_x(s, i);
      const Eigen::Vector3d d(tx, 0.0, -1.0);
      const double den = n_view.dot(d);
      if (std::abs(den) < 1e-9) continue;
      const double z = n_view.dot(p_view - laser) / den;
      if (!(z > s.range_min_mm + 1.0 && z < s.range_max_mm - 1.0)) continue;
      const Eigen::Vector3d hit = laser + z * d;
      if (n_view.dot(laser - hit) <= 0.0 || n_view.dot(receiver - hit) <= 0.0) continue;
      if (!inside(img.pose.camera_to_object * hit)) continue;
      out.push_back({theta_xz(n_view, tx), img.at(i, j).valid()});
    }
  }
  return out;
}

Eigen::Vector3d oriented(Eigen::Vector3d n, const Eigen::Vector3d& towards) { return n.dot(towards) < 0.0 ? -n : n; }

}  // namespace

sp::JointVector look_at(const sp::CellModel& cell, const Eigen::Vector3d& p, double standoff, double tilt, double table,
                        double scan_length, const std::string& what) {
  const sp::IkResult ik = sp::look_at(cell, p, standoff, tilt, table, scan_length);
  if (!ik.ok) throw DataError(what + ": the cell cannot reach the scan pose (" + ik.why + ")");
  return ik.q;
}

// ---------------------------------------------------------------------------------------------------------
// Sensor runs.

namespace {

/// A plane scan kept for the noise fits: its view-frame samples and fitted plane.
struct PlaneScan {
  std::vector<Eigen::Vector3d> pts;
  Eigen::Vector3d n, p0;
};

const Eigen::Vector3d kPlateCentre(0.0, 0.0, kPlateThicknessMm);

bool on_plate(const Eigen::Vector3d& t) {
  return std::abs(t.x()) < 0.5 * kPlateSideMm - 3.0 && std::abs(t.y()) < 0.5 * kPlateSideMm - 3.0 && std::abs(t.z() - kPlateThicknessMm) < 1.0;
}

/// 1. Depth noise against range: the plate face-on at `o.standoffs` stand-offs across the range; each scan's
/// residuals normal to its fitted plane give σz at that depth (fit_noise below).
std::vector<PlaneScan> scan_noise_plates(const RunContext& ctx, const SensorRunOptions& o, SensorResult& r) {
  const sp::SensorModel& s = ctx.sensor;
  std::vector<PlaneScan> scans;
  for (int k = 0; k < o.standoffs; ++k) {
    const double span = s.range_max_mm - s.range_min_mm;
    const double standoff = s.range_min_mm + span * (0.1 + 0.75 * k / std::max(1, o.standoffs - 1));
    const std::string what = "noise scan " + std::to_string(k + 1) + " at stand-off " + std::to_string(static_cast<int>(standoff)) + " mm";
    // The table turned half a turn: the ramp stands on the far side, out of the plate's rays.
    const sp::JointVector q = look_at(ctx.cell, kPlateCentre - Eigen::Vector3d(o.plate_aim_x_mm, 0, 0), standoff, o.plate_tilt_rad,
                                      std::numbers::pi, o.scan_length_mm, what);
    const sp::RangeImage img = ctx.scan(q, o.scan_length_mm);
    ++r.scans;
    const std::vector<Eigen::Vector3d> pts = view_points_where(img, on_plate);
    if (pts.size() < 1000)
      throw DataError(what + ": " + std::to_string(pts.size()) + " samples on the plate (at least 1000 needed; is the plate on the table?)");
    PlaneFit f = fit_plane(pts, what);
    f.normal = oriented(f.normal, -f.point);
    scans.push_back({pts, f.normal, f.point});
  }
  return scans;
}

/// The edge between rays that return and rays that do not, from the rays' incidence θ_xz; where noise makes
/// the two overlap, the threshold that misclassifies the fewest rays.
Estimate grazing_threshold(const std::vector<RayOutcome>& xz, double expected_rad) {
  double returned_max = -1.0, missing_min = 10.0;
  std::size_t returned = 0, missing = 0;
  for (const auto& x : xz) {
    if (x.returned) {
      returned_max = std::max(returned_max, x.theta_xz);
      ++returned;
    } else {
      missing_min = std::min(missing_min, x.theta_xz);
      ++missing;
    }
  }
  if (returned < 100 || missing < 100)
    throw DataError("t_xz: the grazing scans do not straddle the threshold (" + std::to_string(returned) + " rays returned, " +
                    std::to_string(missing) + " missing; expected around " + deg(expected_rad) + ")");
  if (missing_min < returned_max) {
    std::vector<RayOutcome> sorted = xz;
    std::sort(sorted.begin(), sorted.end(), [](const RayOutcome& x, const RayOutcome& y) { return x.theta_xz < y.theta_xz; });
    long wrong = static_cast<long>(returned), best_wrong = wrong;  // threshold below every ray: all returned are wrong
    std::size_t best = 0;
    for (std::size_t i = 0; i + 1 < sorted.size(); ++i) {
      wrong += sorted[i].returned ? -1 : 1;
      if (wrong < best_wrong) {
        best_wrong = wrong;
        best = i;
      }
    }
    returned_max = sorted[best].theta_xz;
    missing_min = sorted[best + 1].theta_xz;
  }
  return {0.5 * (returned_max + missing_min), std::max(0.5 * (missing_min - returned_max), 1e-4)};
}

/// 2. t_xz: the plate seen ever more obliquely; within a scan θ_xz sweeps across the fan, so the threshold is
/// the edge between rays that return and rays that do not. The scans with enough plate samples also lean the
/// plane in the camera's x: kept in `oblique` for the lateral noise.
Estimate measure_t_xz(const RunContext& ctx, const SensorRunOptions& o, SensorResult& r, std::vector<PlaneScan>& oblique) {
  const sp::SensorModel& s = ctx.sensor;
  std::vector<RayOutcome> xz;
  for (int k = 0; k < o.t_xz_tilts; ++k) {
    const double boresight = s.grazing_xz_rad + 0.2 * (k - 0.5 * (o.t_xz_tilts - 1));  // from the plate normal
    const double tilt = 0.5 * std::numbers::pi - boresight;
    const std::string what = "grazing scan " + std::to_string(k + 1) + " (boresight " + deg(boresight) + " from the plate normal)";
    const sp::JointVector q = look_at(ctx.cell, kPlateCentre, 0.5 * (s.range_min_mm + s.range_max_mm) * 0.8, tilt,
                                      std::numbers::pi, o.scan_length_mm, what);
    const sp::RangeImage img = ctx.scan(q, o.scan_length_mm);
    ++r.scans;
    const std::vector<Eigen::Vector3d> pts = view_points_where(img, on_plate);
    // The plane from the samples where there are enough, else from the model: the plate's top in the view.
    Eigen::Vector3d n, p;
    if (pts.size() >= 200) {
      const PlaneFit f = fit_plane(pts, what);
      n = oriented(f.normal, -f.point);
      p = f.point;
      oblique.push_back({pts, n, p});
    } else {
      const Eigen::Isometry3d to_view = img.pose.camera_to_object.inverse();
      n = to_view.linear() * Eigen::Vector3d::UnitZ();
      p = to_view * kPlateCentre;
    }
    const auto rays = rays_on_plane(img, s, n, p, on_plate);
    xz.insert(xz.end(), rays.begin(), rays.end());
  }
  const Estimate t = grazing_threshold(xz, s.grazing_xz_rad);
  ctx.log("t_xz " + deg(t.value) + " ± " + deg(t.ci95) + " from " + std::to_string(xz.size()) + " rays");
  return t;
}

/// 3. t_yz: the ramp turned on the table; each scan's yield (rays with θ_xz safely below t_xz that return),
/// then bisection on the table angle where the yield falls through the threshold. The ramp scans lean the
/// plane in the camera's y: kept in `oblique`.
Estimate measure_t_yz(const RunContext& ctx, const SensorRunOptions& o, SensorResult& r, std::vector<PlaneScan>& oblique) {
  const sp::SensorModel& s = ctx.sensor;
  const Ramp ramp = o.ramp;
  auto on_face = [&](const Eigen::Vector3d& t) { return on_ramp_face(ramp, t, 3.0, 1.0); };
  const double standoff = s.range_min_mm + 0.3 * (s.range_max_mm - s.range_min_mm);
  auto ramp_scan = [&](double table) -> std::pair<double, double> {
    const std::string what = "ramp scan at table " + deg(table);
    const sp::JointVector q = look_at(ctx.cell, ramp.centre(), standoff, o.ramp_tilt_rad, table, 40.0, what);
    const sp::RangeImage img = ctx.scan(q, 40.0);
    ++r.scans;
    const Eigen::Isometry3d to_view = img.pose.camera_to_object.inverse();
    Eigen::Vector3d n = to_view.linear() * ramp.normal(), p = to_view * ramp.centre();
    const std::vector<Eigen::Vector3d> pts = view_points_where(img, on_face);
    if (pts.size() >= 200) {
      const PlaneFit f = fit_plane(pts, what);
      n = oriented(f.normal, n);
      p = f.point;
      oblique.push_back({pts, n, p});
    }
    std::size_t eligible = 0, returned = 0;
    for (const auto& x : rays_on_plane(img, s, n, p, on_face))
      if (x.theta_xz < r.t_xz_rad.value - 0.03) {
        ++eligible;
        returned += x.returned;
      }
    if (eligible < 100)
      throw DataError(what + ": only " + std::to_string(eligible) + " rays reach the ramp's face below t_xz (is the ramp on the table?)");
    const double y = static_cast<double>(returned) / static_cast<double>(eligible), th = theta_yz(n);
    r.yield_vs_theta_yz.emplace_back(th, y);
    ctx.log(what + ": theta_yz " + deg(th) + ", yield " + std::to_string(y));
    return {th, y};
  };
  double lo = 0.0, hi = 0.0;  // table angles: at lo the ramp does not measure (steep), at hi it does
  double th_lo = 0.0, th_hi = 0.0;
  bool bracketed = false;
  auto [th_prev, y_prev] = ramp_scan(0.0);
  if (y_prev >= o.yield_threshold)
    throw DataError("t_yz: the ramp at its steepest (" + deg(th_prev) + ") still measures: t_yz is above the ramp's slope");
  // Turning the table this way lowers θ_yz while the camera's own tilt keeps θ_xz moderate (the other way
  // the two add up and θ_xz passes t_xz first).
  for (int k = 1; k <= 9 && !bracketed; ++k) {
    const double table = -k * 10.0 * std::numbers::pi / 180.0;
    const auto [th, y] = ramp_scan(table);
    if (y >= o.yield_threshold) {
      lo = table + 10.0 * std::numbers::pi / 180.0;
      hi = table;
      th_lo = th_prev;
      th_hi = th;
      bracketed = true;
    }
    th_prev = th;
  }
  if (!bracketed) throw DataError("t_yz: no ramp scan measured down to θ_yz " + deg(th_prev));
  for (int b = 0; b < o.t_yz_bisections; ++b) {
    const double mid = 0.5 * (lo + hi);
    const auto [th, y] = ramp_scan(mid);
    if (y >= o.yield_threshold) {
      hi = mid;
      th_hi = th;
    } else {
      lo = mid;
      th_lo = th;
    }
  }
  const Estimate t{0.5 * (th_lo + th_hi), std::max(0.5 * std::abs(th_lo - th_hi), 1e-4)};
  ctx.log("t_yz " + deg(t.value) + " ± " + deg(t.ci95));
  return t;
}

/// σz per stand-off from the face-on scans: the residuals normal to the plane with the lateral noise's share
/// (C_x, C_y given) removed; C_z from σz = C_z z² by least squares.
void fit_depth_noise(const std::vector<PlaneScan>& noise_scans, double cx, double cy, SensorResult& r) {
  std::vector<double> z2, sig;
  r.noise.clear();
  for (const auto& sc : noise_scans) {
    double acc = 0.0;
    std::vector<double> depths;
    for (const auto& p : sc.pts) {
      const double z = -p.z(), res = (p - sc.p0).dot(sc.n);
      depths.push_back(z);
      const double lateral_share = std::pow(sc.n.x() * cx * z, 2) + std::pow(sc.n.y() * cy * z, 2);
      acc += (res * res - lateral_share) / (sc.n.z() * sc.n.z() * z * z * z * z);
    }
    std::nth_element(depths.begin(), depths.begin() + static_cast<long>(depths.size() / 2), depths.end());
    const double zm = depths[depths.size() / 2], c2 = acc / static_cast<double>(sc.pts.size() - 3);
    if (!(c2 > 0.0)) throw DataError("noise scans: no depth noise left after the lateral share (plate not flat?)");
    r.noise.push_back({zm, std::sqrt(c2) * zm * zm, sc.pts.size()});
    z2.push_back(zm * zm);
    sig.push_back(r.noise.back().sigma_z_mm);
  }
  const ProportionalFit cz = fit_proportional(z2, sig, "C_z fit");
  r.cz_per_mm = {cz.k, std::max(cz.ci95(), 1.96 * cz.k / std::sqrt(2.0 * static_cast<double>(r.noise.front().samples)))};
  r.noise_fit_rms_mm = cz.rms;
}

/// Lateral noise (eq. 3.3): on a plane whose normal n leans in the camera's x or y, the residuals normal to it
/// carry n_x σx and n_y σy beside n_z σz: r² ≈ (n_x z)² C_x² + (n_y z)² C_y² + (n_z σz)², linear in (C_x², C_y²)
/// with σz from C_z. The grazing plate scans lean in x, the ramp scans in y.
void fit_lateral_noise(const std::vector<PlaneScan>& oblique_scans, SensorResult& r) {
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  double cc = 0.0;
  std::size_t n = 0;
  for (const auto& sc : oblique_scans) {
    const double cos_yz = sc.n.z() / std::hypot(sc.n.y(), sc.n.z());
    for (const auto& q : sc.pts) {
      const double z = -q.z(), res = (q - sc.p0).dot(sc.n), sz = r.cz_per_mm.value * z * z / cos_yz;
      const Eigen::Vector2d a(std::pow(sc.n.x() * z, 2), std::pow(sc.n.y() * z, 2));
      const double c = res * res - std::pow(sc.n.z() * sz, 2);
      ata += a * a.transpose();
      atb += a * c;
      cc += c * c;
      ++n;
    }
  }
  if (n < 1000 || std::abs(ata.determinant()) < 1e-12 * ata.squaredNorm())
    throw DataError("C_x, C_y: too few oblique samples to separate the lateral noise");
  const Eigen::Vector2d c2 = ata.ldlt().solve(atb);
  const double ss = std::max(0.0, cc - 2.0 * c2.dot(atb) + c2.dot(ata * c2));
  const Eigen::Matrix2d cov = ss / static_cast<double>(n - 2) * ata.inverse();
  auto root = [&](int k) {
    const double v = std::max(c2(k), 0.0), se2 = std::sqrt(std::max(cov(k, k), 0.0)), value = std::sqrt(v);
    return Estimate{value, value > 0.0 ? 1.96 * se2 / (2.0 * value) : 1.96 * std::sqrt(se2)};
  };
  r.cx = root(0);
  r.cy = root(1);
}

}  // namespace

// Sensor: C_z from a plate across the range, t_xz from the plate at grazing tilts, t_yz from a ramp turned on
// the turntable (θ_yz of a line scan is set by the surface alone, so the ramp's slope seen along the camera's
// y is what varies it).
SensorResult run_sensor(const RunContext& ctx, const SensorRunOptions& o) {
  SensorResult r;
  std::vector<PlaneScan> oblique;
  const std::vector<PlaneScan> noise = scan_noise_plates(ctx, o, r);
  r.t_xz_rad = measure_t_xz(ctx, o, r, oblique);
  r.t_yz_rad = measure_t_yz(ctx, o, r, oblique);
  // σz per stand-off (C_z) and the lateral coefficients (C_x, C_y) each need the other to remove its share
  // of the residuals: alternate, starting from the model's C_x, C_y.
  double cx = ctx.sensor.noise_cx, cy = ctx.sensor.noise_cy;
  for (int pass = 0; pass < 4; ++pass) {
    fit_depth_noise(noise, cx, cy, r);
    fit_lateral_noise(oblique, r);
    cx = r.cx.value;
    cy = r.cy.value;
  }
  for (std::size_t k = 0; k < r.noise.size(); ++k)
    ctx.log("noise scan " + std::to_string(k + 1) + ": depth " + std::to_string(r.noise[k].depth_mm) + " mm, sigma_z " +
            std::to_string(r.noise[k].sigma_z_mm) + " mm from " + std::to_string(r.noise[k].samples) + " samples");
  ctx.log("C_z " + std::to_string(r.cz_per_mm.value) + ", C_x " + std::to_string(r.cx.value) + " ± " + std::to_string(r.cx.ci95) +
          ", C_y " + std::to_string(r.cy.value) + " ± " + std::to_string(r.cy.ci95));
  return r;
}

// ---------------------------------------------------------------------------------------------------------
// Turntable axis: one sphere off the axis, a fixed camera, N table angles; the sphere's centres (in the world,
// through the camera's own pose, which the table does not move) lie on a circle about the axis.

AxisResult run_turntable_axis(const RunContext& ctx, const AxisRunOptions& o) {
  if (o.target.centres.size() != 1) throw DataError("turntable axis run: the target must be one sphere");
  AxisResult r;
  const Eigen::Vector3d c0 = o.target.centres.front();
  const Eigen::Vector3d aim(0.0, 0.0, c0.z());  // on the axis at the sphere's height: the camera never moves
  double sphere_ss = 0.0;
  std::size_t sphere_n = 0;
  for (int k = 0; k < o.angles; ++k) {
    const double table = -std::numbers::pi + 2.0 * std::numbers::pi * k / o.angles;
    const std::string what = "sphere scan at table " + deg(table);
    const sp::JointVector q = look_at(ctx.cell, aim, o.standoff_mm, o.camera_tilt_rad, table, o.scan_length_mm, what);
    const sp::RangeImage img = ctx.scan(q, o.scan_length_mm);
    ++r.scans;
    const Samples smp = samples_of(img);
    std::vector<Eigen::Vector3d> pts;
    for (const auto& t : smp.target)
      if ((t - c0).norm() < o.target.radius_mm + 5.0) pts.push_back(t);
    const SphereFit f = fit_sphere(pts, what, o.target.radius_mm);
    sphere_ss += f.rms * f.rms * static_cast<double>(f.n);
    sphere_n += f.n;
    // Target frame → world with the model's table angle: the samples came through the model's kinematics, so
    // this undoes exactly what produced them and leaves the camera's world pose, which the table cannot move.
    r.centres_world_mm.push_back(sp::table_to_world(ctx.cell, q[0]) * ctx.cell.object_on_table * f.centre);
  }
  const CircleFit c = fit_circle(r.centres_world_mm, "turntable axis circle");
  r.direction = c.normal.z() < 0.0 ? Eigen::Vector3d(-c.normal) : c.normal;
  r.point_mm = c.centre - (c.centre.z() / r.direction.z()) * r.direction;
  r.circle_radius_mm = c.radius;
  r.circle_rms_mm = c.rms;
  r.sphere_rms_mm = sphere_n ? std::sqrt(sphere_ss / static_cast<double>(sphere_n)) : 0.0;
  const double spread = std::sqrt(0.5 * static_cast<double>(o.angles));
  r.direction_ci95_rad = 1.96 * c.rms / (c.radius * spread);
  r.point_ci95_mm = 1.96 * c.rms / spread * (1.0 + c.centre.z() / c.radius);
  ctx.log("axis direction " + std::to_string(r.direction.x()) + " " + std::to_string(r.direction.y()) + " " +
          std::to_string(r.direction.z()) + ", point " + std::to_string(r.point_mm.x()) + " " + std::to_string(r.point_mm.y()) +
          ", circle r " + std::to_string(c.radius) + " rms " + std::to_string(c.rms));
  return r;
}

// ---------------------------------------------------------------------------------------------------------
// Positioner repeatability: return to each measuring pose from a different detour each time; the tripod's
// three sphere centres fix each return's achieved pose relative to the mean of the returns (thesis 7.2.4:
// σ_p the camera position, σ_a its boresight direction, σ_t the twist about it).

PositionerResult run_positioner(const RunContext& ctx, const PositionerRunOptions& o) {
  if (o.target.centres.size() != 3) throw DataError("positioner run: the target must be three spheres");
  if (o.repeats < 3) throw DataError("positioner run: at least 3 repeats per pose");
  PositionerResult r;
  std::mt19937_64 rng(o.seed);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& c : o.target.centres) centroid += c / 3.0;
  double ss_p = 0.0, ss_a = 0.0, ss_t = 0.0, sphere_ss = 0.0;
  std::size_t sphere_n = 0;
  int dof = 0;
  const sp::JointVector home = ctx.cell.home();
  for (int k = 0; k < o.poses; ++k) {
    const double table = 2.0 * std::numbers::pi * k / o.poses - std::numbers::pi / 2;
    const double tilt = k % 2 ? 1.05 : 1.15;
    const std::string what = "positioner pose " + std::to_string(k + 1);
    const sp::JointVector q = look_at(ctx.cell, centroid, o.standoff_mm, tilt, table, o.scan_length_mm, what);
    std::vector<std::array<Eigen::Vector3d, 3>> measured;
    Eigen::Isometry3d nominal = Eigen::Isometry3d::Identity();
    for (int m = 0; m < o.repeats; ++m) {
      // A detour from a random direction: every axis off by up to a tenth of its travel, around home.
      sp::JointVector detour = home;
      for (std::size_t a = 0; a < detour.size(); ++a) {
        const auto& ax = ctx.cell.axes[a];
        std::uniform_real_distribution<double> u(-0.1, 0.1);
        detour[a] = std::clamp(home[a] + u(rng) * (ax.max - ax.min), ax.min, ax.max);
      }
      ctx.move(detour);
      const sp::RangeImage img = ctx.scan(q, o.scan_length_mm);
      ++r.scans;
      nominal = img.pose.camera_to_object;
      const Samples smp = samples_of(img);
      std::array<std::vector<Eigen::Vector3d>, 3> groups;
      for (const auto& t : smp.target)
        for (int i = 0; i < 3; ++i)
          if ((t - o.target.centres[static_cast<std::size_t>(i)]).norm() < o.target.radius_mm + 6.0) groups[static_cast<std::size_t>(i)].push_back(t);
      std::array<Eigen::Vector3d, 3> centres;
      for (int i = 0; i < 3; ++i) {
        const SphereFit f = fit_sphere(groups[static_cast<std::size_t>(i)], what + " repeat " + std::to_string(m + 1) + " sphere " + std::to_string(i + 1), o.target.radius_mm);
        centres[static_cast<std::size_t>(i)] = f.centre;
        sphere_ss += f.rms * f.rms * static_cast<double>(f.n);
        sphere_n += f.n;
      }
      measured.push_back(centres);
    }
    std::array<Eigen::Vector3d, 3> mean{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
    for (const auto& c : measured)
      for (int i = 0; i < 3; ++i) mean[static_cast<std::size_t>(i)] += c[static_cast<std::size_t>(i)] / static_cast<double>(measured.size());
    // A line scan with a pose error is not a rigid copy of the object: the camera's rotation error r is
    // fixed in the camera frame, which slides along its y during the sweep, so every profile turns about its
    // own laser origin. To first order a point c of the view frame (camera at mid-sweep) is measured at
    //   m = c + c⊥ × ω + b,   c⊥ = (c_x, 0, c_z),  ω the rotation vector of r,  b = −e (e: position error),
    // which is linear in (ω, b): three sphere centres at different depths and across the profile fix all six.
    const Eigen::Isometry3d to_view = nominal.inverse();
    std::array<Eigen::Vector3d, 3> ref;
    for (int i = 0; i < 3; ++i) ref[static_cast<std::size_t>(i)] = to_view * mean[static_cast<std::size_t>(i)];
    for (const auto& c : measured) {
      Eigen::Matrix<double, 9, 6> a = Eigen::Matrix<double, 9, 6>::Zero();
      Eigen::Matrix<double, 9, 1> rhs;
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d& rc = ref[static_cast<std::size_t>(i)];
        const Eigen::Vector3d perp(rc.x(), 0.0, rc.z());
        Eigen::Matrix3d skew;
        skew << 0, -perp.z(), perp.y(), perp.z(), 0, -perp.x(), -perp.y(), perp.x(), 0;
        a.block<3, 3>(3 * i, 0) = skew;
        a.block<3, 3>(3 * i, 3) = Eigen::Matrix3d::Identity();
        rhs.segment<3>(3 * i) = to_view * c[static_cast<std::size_t>(i)] - rc;
      }
      const Eigen::Matrix<double, 6, 1> x = a.colPivHouseholderQr().solve(rhs);
      if (!x.allFinite()) throw DataError(what + ": the three sphere centres do not fix the pose (collinear?)");
      ss_p += x.tail<3>().squaredNorm();
      ss_a += x(0) * x(0) + x(1) * x(1);  // boresight tilt: rotation about the camera's x and y
      ss_t += x(2) * x(2);                // twist about the boresight
    }
    dof += o.repeats - 1;  // one mean per pose
  }
  auto est = [&](double ss) {
    const double sigma = std::sqrt(ss / dof);
    return Estimate{sigma, 1.96 * sigma / std::sqrt(2.0 * dof)};
  };
  r.sigma_p_mm = est(ss_p);
  r.sigma_a_rad = est(ss_a);
  r.sigma_t_rad = est(ss_t);
  r.sphere_rms_mm = sphere_n ? std::sqrt(sphere_ss / static_cast<double>(sphere_n)) : 0.0;
  ctx.log("sigma_p " + std::to_string(r.sigma_p_mm.value) + " mm, sigma_a " + deg(r.sigma_a_rad.value) + ", sigma_t " +
          deg(r.sigma_t_rad.value) + " from " + std::to_string(r.scans) + " scans");
  return r;
}

}  // namespace scancell::calibration
