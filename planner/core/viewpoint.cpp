#include "planner/core/viewpoint.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include "common/errors.hpp"
#include "planner/geometry/point_kdtree.hpp"

namespace scancell::planner {

const char* to_string(ViewSource s) {
  switch (s) {
    case ViewSource::optimal_zone: return "optimal_zone";
    case ViewSource::single_best: return "single_best";
    case ViewSource::footprint_aim: return "footprint_aim";
    case ViewSource::self_aim: return "self_aim";
    case ViewSource::open_direction: return "open_direction";
  }
  return "unknown";
}

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

Eigen::Vector3d twist_reference_x(const Eigen::Vector3d& zc) {
  const Eigen::Vector3d u = std::abs(zc.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  return u.cross(zc).normalized();
}

/// The rough model's points in a k-d tree (nanoflann). The clearance and local-patch tests visit the points
/// near a position, not all of them: a 26k-row mesh as given asks up to nine of each per position. A query
/// gives its points in index order, a hair beyond its radius for rounding, and each caller applies its own
/// test, so answers and sums are those of a walk over every point.
class RoughPointTree {
 public:
  explicit RoughPointTree(const RoughModel& rough)
      : adaptor_{&rough.points}, index_(3, adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    index_.buildIndex();
  }
  RoughPointTree(const RoughPointTree&) = delete;  // the index holds a reference to the adaptor
  RoughPointTree& operator=(const RoughPointTree&) = delete;

  /// The points within `radius_mm` of p, ascending (into `out`, which it clears).
  void within(const Eigen::Vector3d& p, double radius_mm, std::vector<std::uint32_t>& out) const {
    thread_local std::vector<std::pair<std::uint32_t, double>> found;
    thread_local std::vector<std::uint64_t> bits;  // all zero between calls
    found.clear();
    out.clear();
    const double r2 = radius_mm * radius_mm * (1.0 + 1e-9) + 1e-9;
    index_.radiusSearch(p.data(), r2, found, nanoflann::SearchParams(32, 0.0f, false));
    if (found.empty()) return;
    // Ascending by a bit per point rather than a sort: a patch holds thousands of a dense mesh's points.
    bits.resize(std::max(bits.size(), adaptor_.pts->size() / 64 + 1), 0);
    std::uint32_t lo = found.front().first, hi = lo;
    for (const auto& [i, d2] : found) bits[i / 64] |= std::uint64_t{1} << (i % 64), lo = std::min(lo, i), hi = std::max(hi, i);
    for (std::uint32_t w = lo / 64; w <= hi / 64; ++w)
      for (std::uint64_t b = std::exchange(bits[w], 0); b; b &= b - 1) out.push_back(w * 64 + static_cast<std::uint32_t>(__builtin_ctzll(b)));
  }

 private:
  PointsAdaptor adaptor_;
  PointKdTree index_;
};

/// Whether a camera position keeps the clearance from every rough-model point.
bool keeps_clearance(const RoughModel& rough, const RoughPointTree& tree, const Eigen::Vector3d& pos, double clearance_mm) {
  thread_local std::vector<std::uint32_t> near;
  tree.within(pos, clearance_mm, near);
  for (const auto i : near)
    if ((rough.points[i] - pos).squaredNorm() < clearance_mm * clearance_mm) return false;
  return true;
}

/// The bisector-tilted twin of a view aimed at `target`: turned about camera x by `tilt` so the target's
/// normal bisects the laser and receiver rays, at the same stand-off from the target.
Viewpoint bisector_twin(const Viewpoint& v, const Eigen::Vector3d& target, double standoff, double tilt) {
  const Eigen::Matrix3d rt = camera_rotation(v.axis, v.twist_rad, tilt);
  Viewpoint t = v;
  t.axis = -rt.col(2);
  t.twist_rad = twist_towards(t.axis, rt.col(1));
  t.position = target + standoff * rt.col(2);
  t.tilt_rad = tilt;
  return t;
}

/// What the neighbourhood of a targeted point tells the VARIABLE rules.
struct Patch {
  double rise_mm = 0.0;                            // R_a: how far patch points stand towards the camera
  Eigen::Vector3d plane_normal = Eigen::Vector3d::Zero();
  double nearest_mm = std::numeric_limits<double>::infinity();  // from a camera position to any point
};

}  // namespace

std::vector<std::uint32_t> farthest_point_sample(const RoughModel& rough, std::size_t count, double normal_weight_mm) {
  const std::size_t n = rough.size();
  if (count >= n) {
    std::vector<std::uint32_t> all(n);
    for (std::uint32_t i = 0; i < n; ++i) all[i] = i;
    return all;
  }
  std::vector<std::uint32_t> picked;
  picked.reserve(count);
  std::vector<double> d2(n, std::numeric_limits<double>::infinity());
  const double w2 = normal_weight_mm * normal_weight_mm;
  std::uint32_t next = 0;  // start from row 0: deterministic
  struct Best {
    double d2;
    std::uint32_t row;
  };
  while (picked.size() < count) {
    picked.push_back(next);
    const Eigen::Vector3d p = rough.points[next], nn = rough.normals[next];
    const Best best = tbb::parallel_reduce(
        tbb::blocked_range<std::uint32_t>(0, static_cast<std::uint32_t>(n), 4096), Best{-1.0, 0},
        [&](const auto& r, Best b) {
          for (std::uint32_t i = r.begin(); i != r.end(); ++i) {
            const double d = (rough.points[i] - p).squaredNorm() + w2 * (rough.normals[i] - nn).squaredNorm();
            if (d < d2[i]) d2[i] = d;
            if (d2[i] > b.d2) b = {d2[i], i};
          }
          return b;
        },
        [](const Best& a, const Best& b) { return (a.d2 > b.d2 || (a.d2 == b.d2 && a.row < b.row)) ? a : b; });
    if (best.d2 <= 0.0) break;  // only duplicates left
    next = best.row;
  }
  return picked;
}

Eigen::Matrix3d camera_rotation(const Eigen::Vector3d& axis, double twist_rad) {
  const Eigen::Vector3d zc = -axis.normalized();
  const Eigen::Vector3d x0 = twist_reference_x(zc);
  const Eigen::Vector3d y0 = zc.cross(x0);
  const Eigen::Vector3d xc = std::cos(twist_rad) * x0 + std::sin(twist_rad) * y0;
  Eigen::Matrix3d r;
  r.col(0) = xc;
  r.col(1) = zc.cross(xc);
  r.col(2) = zc;
  return r;
}

Eigen::Matrix3d camera_rotation(const Eigen::Vector3d& axis, double twist_rad, double tilt_rad) {
  Eigen::Matrix3d r = camera_rotation(axis, twist_rad);
  if (tilt_rad == 0.0) return r;
  const Eigen::Vector3d y0 = r.col(1), z0 = r.col(2);
  r.col(2) = std::cos(tilt_rad) * z0 - std::sin(tilt_rad) * y0;
  r.col(1) = std::sin(tilt_rad) * z0 + std::cos(tilt_rad) * y0;
  return r;
}

double twist_towards(const Eigen::Vector3d& axis, const Eigen::Vector3d& dir) {
  const Eigen::Vector3d zc = -axis.normalized();
  const Eigen::Vector3d perp = dir - dir.dot(zc) * zc;
  if (perp.norm() < 1e-9) return 0.0;
  const Eigen::Vector3d yc = perp.normalized();
  const Eigen::Vector3d xc = yc.cross(zc);
  const Eigen::Vector3d x0 = twist_reference_x(zc);
  const Eigen::Vector3d y0 = zc.cross(x0);
  double t = std::atan2(xc.dot(y0), xc.dot(x0));
  return t < 0.0 ? t + kTwoPi : t;
}

Viewpoint viewpoint_from_pose(const Eigen::Matrix3d& r, const Eigen::Vector3d& position, double scan_length_mm) {
  Viewpoint v;
  const Eigen::Vector3d zc = r.col(2).normalized();
  v.axis = -zc;
  const Eigen::Vector3d x0 = twist_reference_x(zc);
  const Eigen::Vector3d y0 = zc.cross(x0);
  v.twist_rad = std::atan2(r.col(0).dot(y0), r.col(0).dot(x0));
  v.position = position;
  v.scan_length_mm = scan_length_mm;
  return v;
}

Eigen::Matrix3d Viewpoint::rotation() const {
  // `axis` and `twist_rad` describe the actual frame, tilted or not; tilt_rad only records how it was made.
  return camera_rotation(axis, twist_rad);
}

Eigen::Matrix4d Viewpoint::transform() const {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = rotation();
  t.topRightCorner<3, 1>() = position;
  return t;
}

std::array<long long, 12> Viewpoint::pose_key() const {
  const Eigen::Matrix4d m = transform();
  std::array<long long, 12> key{};
  for (int k = 0; k < 12; ++k) key[k] = std::llround(m(k / 4, k % 4) * (k % 4 == 3 ? 1e6 : 1e9));
  return key;
}

namespace {

/// The longest sweep whose eq. 3.8 density meets the spec at `range_mm` with the normal's incidence cosines
/// `c_xz`, `c_yz` (Δx = z Φx / (N_x − 1) / c_xz, Δy = L / (N_y − 1) / c_yz); the shortest allowed when none does.
double scan_length_at_incidence_mm(const SensorModel& sensor, const ModelSpec& spec, double range_mm, double c_xz, double c_yz) {
  const double dx = range_mm * sensor.fov_x_rad / (sensor.samples_x - 1) / c_xz;
  const double dy2 = 1.0 / spec.density_per_mm2 - dx * dx;
  if (dy2 <= 0.0) return sensor.scan_length_min_mm;
  const double length = std::sqrt(dy2) * c_yz * (sensor.samples_y - 1);
  return std::clamp(length, sensor.scan_length_min_mm, sensor.scan_length_max_mm);
}

}  // namespace

double design_scan_length_mm(const SensorModel& sensor, const ModelSpec& spec, double range_mm,
                             double design_incidence_rad) {
  if (sensor.kind != SensorKind::line_scan) return 0.0;
  const double c = std::cos(design_incidence_rad);
  return scan_length_at_incidence_mm(sensor, spec, range_mm, c, c);
}

double aimed_scan_length_mm(const SensorModel& sensor, const ModelSpec& spec, double range_mm, const Eigen::Matrix3d& rotation,
                            const Eigen::Vector3d& normal, double design_incidence_rad) {
  if (sensor.kind != SensorKind::line_scan) return 0.0;
  const Eigen::Vector3d n = rotation.transpose() * normal;  // camera frame: a facing surface has n.z > 0
  if (!(n.z() > 0.0)) return design_scan_length_mm(sensor, spec, range_mm, design_incidence_rad);
  const double c = std::cos(design_incidence_rad);
  return scan_length_at_incidence_mm(sensor, spec, range_mm, std::min(c, n.z() / std::hypot(n.x(), n.z())),
                                     std::min(c, n.z() / std::hypot(n.y(), n.z())));
}

namespace {

/// Viewpoint positions: RM_v, a d_v-times sparser subset of the rough-model rows (DECOUPLED), or every row
/// (VARIABLE), sorted. The thesis decimates RM_s again; quadric decimation leaves flat regions arbitrarily
/// sampled (it may strip a plate's corners of every nearby position), so we take a farthest-point sample
/// instead, in position and normal together: it spreads positions evenly, keeps extremities, samples curved
/// regions more densely, and never lets the two sides of a thin wall share one position.
std::vector<std::uint32_t> viewpoint_positions(const RoughModel& rough, const ViewpointSettings& st, double footprint_half_x,
                                               GenerationReport& rep) {
  const bool decoupled = st.scheme == ViewpointScheme::decoupled;
  const std::size_t by_decimation =
      decoupled ? std::max<std::size_t>(1, rough.size() / static_cast<std::size_t>(st.position_decimation)) : rough.size();
  std::size_t n_positions = by_decimation;
  if (decoupled && st.min_position_spacing_fraction > 0.0) {
    // The footprint, not the mesh, sets how finely positions need to be sampled: positions a few percent of
    // its width apart see nearly the same rows (a view's coverage varies slowly with its position).
    const double spacing_mm = st.min_position_spacing_fraction * 2.0 * footprint_half_x;
    const double area = std::accumulate(rough.area_mm2.begin(), rough.area_mm2.end(), 0.0);
    n_positions = std::min(n_positions, std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(area / (spacing_mm * spacing_mm)))));
  }
  rep.positions_by_decimation = by_decimation;
  std::vector<std::uint32_t> target_rows = farthest_point_sample(rough, n_positions, footprint_half_x);
  std::sort(target_rows.begin(), target_rows.end());  // candidate order follows the rows, not the sampling order
  rep.positions = target_rows.size();
  return target_rows;
}

/// The local patch at row point s with normal n: rough points within the footprint cylinder around the normal
/// that face the same side. Its rise towards the camera sets R_a; its plane sets the VARIABLE twist.
Patch local_patch(const RoughModel& rough, const RoughPointTree& tree, const Eigen::Vector3d& s, const Eigen::Vector3d& n,
                  double patch_radius) {
  Patch patch;
  auto inside = [&](std::size_t i, double& h) {
    const Eigen::Vector3d d = rough.points[i] - s;
    h = d.dot(n);
    return std::abs(h) <= patch_radius && (d - h * n).squaredNorm() <= patch_radius * patch_radius && rough.normals[i].dot(n) > 0.0;
  };
  // The cylinder lies within √2 of its radius from s when n is a unit vector, within (1 + |n|) of it always.
  const double n_norm = n.norm();
  const double reach = patch_radius * (std::abs(n_norm - 1.0) < 1e-6 ? std::sqrt(2.0) * (1.0 + 1e-6) : 1.0 + n_norm);
  thread_local std::vector<std::uint32_t> near;
  tree.within(s, reach, near);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double wsum = 0.0, h = 0.0;
  for (const std::uint32_t i : near) {
    if (!inside(i, h)) continue;
    patch.rise_mm = std::max(patch.rise_mm, h);
    const double w = rough.area_mm2[i];
    centroid += w * rough.points[i];
    wsum += w;
  }
  if (wsum > 0.0) {
    centroid /= wsum;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const std::uint32_t i : near) {
      if (!inside(i, h)) continue;
      const Eigen::Vector3d c = rough.points[i] - centroid;
      cov += rough.area_mm2[i] * c * c.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
    patch.plane_normal = es.eigenvectors().col(0);
    if (patch.plane_normal.dot(n) < 0.0) patch.plane_normal = -patch.plane_normal;
  }
  return patch;
}

/// Collision avoidance zone: the camera must stand outside the object and clear of it. 0 clear, 2 inside
/// (the ray out leaves through a surface), 3 too close.
std::uint8_t obstruction(const RoughModel& rough, const RoughPointTree& tree, const OcclusionScene& scene, double clearance_mm,
                         const Eigen::Vector3d& pos, const Eigen::Vector3d& out_dir) {
  if (!keeps_clearance(rough, tree, pos, clearance_mm)) return 3;
  if (auto hit = scene.first_hit(pos, out_dir, 0.0, 1e7); hit && hit->triangle < rough.triangles.size()) {
    // (Triangles past the rough model's are cell fixtures: leaving through one says nothing of the object.)
    const Triangle& t = rough.triangles[hit->triangle];
    const Eigen::Vector3d fn = (rough.points[t[1]] - rough.points[t[0]]).cross(rough.points[t[2]] - rough.points[t[0]]);
    if (fn.dot(out_dir) > 0.0) return 2;  // leaving through a surface: we were inside
  }
  return 0;
}

/// What every position's candidates share: the sensor's footprint at R_o, the range cap, the scan length.
struct PositionFrame {
  double r_o, footprint_half_x, range_cap, patch_radius;
  int d_t;
};

/// The candidates at row `row` (DECOUPLED: its twist levels, each with its bisector twin where clear), or the
/// reason there are none (1 no normal, 2 inside, 3 clearance).
std::uint8_t views_at(const RoughModel& rough, const RoughPointTree& tree, const OcclusionScene& scene, const SensorModel& sensor,
                      const ModelSpec& spec, const ViewpointSettings& st, const PositionFrame& f, std::uint32_t row,
                      std::vector<Viewpoint>& out) {
  const Eigen::Vector3d s = rough.points[row];
  const Eigen::Vector3d n = rough.normals[row];
  if (n.squaredNorm() < 0.5) return 1;
  const Patch patch = local_patch(rough, tree, s, n, f.patch_radius);
  const double r_a = std::min(patch.rise_mm, st.standoff_adjust_max_mm);
  const double standoff = std::min((f.r_o + r_a) * st.standoff_factor, f.range_cap);
  const Eigen::Vector3d position = s + standoff * n;
  if (const std::uint8_t o = obstruction(rough, tree, scene, st.clearance_mm, position, n)) return o;
  const double scan = design_scan_length_mm(sensor, spec, standoff, st.scan_length_design_incidence_rad);
  // VARIABLE twist: put the receiver (camera +y) as far as possible from the patch plane.
  const double base_twist = twist_towards(-n, patch.plane_normal);
  const double tilt = 0.5 * std::atan2(sensor.baseline_mm, standoff);  // half the triangulation angle
  for (int level = 0; level < f.d_t; ++level) {
    Viewpoint v;
    v.position = position;
    v.axis = -n;
    v.twist_rad = std::fmod(base_twist + kTwoPi * level / f.d_t, kTwoPi);
    v.standoff_mm = standoff;
    v.scan_length_mm = scan;
    v.target_row = static_cast<std::int32_t>(row);
    v.twist_level = level;
    out.push_back(v);
    if (st.bisector_tilt) {
      const Viewpoint t = bisector_twin(v, s, standoff, tilt);
      if (obstruction(rough, tree, scene, st.clearance_mm, t.position, (t.position - s).normalized()) == 0) out.push_back(t);
    }
  }
  return 0;
}

}  // namespace

std::vector<Viewpoint> generate_viewpoints(const RoughModel& rough, const OcclusionScene& scene,
                                           const SensorModel& sensor, const ModelSpec& spec,
                                           const ViewpointSettings& st, GenerationReport* report) {
  if (st.twist_levels < 1) throw ConfigError("viewpoints.twist_levels must be >= 1");
  if (st.position_decimation < 1) throw ConfigError("viewpoints.position_decimation must be >= 1");
  GenerationReport rep;
  // The footprint's half width at R_o: the position spacing's scale, the farthest-point sample's weight on
  // normals, and the local patch's radius.
  PositionFrame f;
  f.r_o = sensor.optimal_standoff_mm;
  f.footprint_half_x = f.r_o * std::tan(0.5 * sensor.fov_x_rad);
  f.d_t = st.scheme == ViewpointScheme::decoupled ? st.twist_levels : 1;
  f.range_cap = std::min(sensor.range_max_mm, max_range_for_precision_mm(sensor, spec));
  const double base_scan = design_scan_length_mm(sensor, spec, f.r_o * st.standoff_factor, st.scan_length_design_incidence_rad);
  const double half_y = sensor.kind == SensorKind::line_scan ? 0.5 * base_scan : f.r_o * std::tan(0.5 * sensor.fov_y_rad);
  f.patch_radius = std::hypot(f.footprint_half_x, half_y);
  const std::vector<std::uint32_t> target_rows = viewpoint_positions(rough, st, f.footprint_half_x, rep);

  std::vector<std::vector<Viewpoint>> per_position(target_rows.size());
  std::vector<std::uint8_t> why(target_rows.size(), 0);  // 0 kept, 1 no normal, 2 inside, 3 clearance
  const RoughPointTree tree(rough);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, target_rows.size(), 8), [&](const auto& range) {
    for (std::size_t k = range.begin(); k != range.end(); ++k)
      why[k] = views_at(rough, tree, scene, sensor, spec, st, f, target_rows[k], per_position[k]);
  });
  std::vector<Viewpoint> out;
  for (std::size_t k = 0; k < per_position.size(); ++k) {
    rep.dropped_no_normal += why[k] == 1;
    rep.dropped_inside += why[k] == 2;
    rep.dropped_clearance += why[k] == 3;
    out.insert(out.end(), per_position[k].begin(), per_position[k].end());
  }
  rep.candidates = out.size();
  if (report) *report = rep;
  return out;
}

namespace {

/// Spread targets for open-direction views: farthest-point order over `rows` (position and normal, as for
/// RM_v), at most `max_rows`, sorted.
std::vector<std::uint32_t> spread_targets(const RoughModel& rough, const SensorModel& sensor, const std::vector<std::uint32_t>& rows,
                                          std::size_t max_rows) {
  std::vector<std::uint32_t> targets;
  const double w2 = std::pow(sensor.optimal_standoff_mm * std::tan(0.5 * sensor.fov_x_rad), 2);
  // Targets closer than a quarter of the footprint width to one another add nothing a neighbour's views
  // do not: stop there, so a cluster of unmeasurable rows (a hole) gets a few targets, not one per row.
  const double min_spacing2 = std::pow(0.5 * sensor.optimal_standoff_mm * std::tan(0.5 * sensor.fov_x_rad), 2);
  std::vector<double> d2(rows.size(), std::numeric_limits<double>::infinity());
  std::size_t next = 0;
  while (targets.size() < std::min(max_rows, rows.size())) {
    targets.push_back(rows[next]);
    const Eigen::Vector3d p = rough.points[rows[next]], nn = rough.normals[rows[next]];
    double best = -1.0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      d2[i] = std::min(d2[i], (rough.points[rows[i]] - p).squaredNorm() + w2 * (rough.normals[rows[i]] - nn).squaredNorm());
      if (d2[i] > best) best = d2[i], next = i;
    }
    if (best < min_spacing2) break;
  }
  std::sort(targets.begin(), targets.end());
  return targets;
}

/// A spread subset of `open` of at most `count`: start nearest the normal `n`, then farthest-first on the sphere.
std::vector<Eigen::Vector3d> spread_directions(const std::vector<Eigen::Vector3d>& open, const Eigen::Vector3d& n, int count) {
  std::vector<Eigen::Vector3d> keep;
  std::size_t first = 0;
  for (std::size_t i = 1; i < open.size(); ++i)
    if (open[i].dot(n) > open[first].dot(n)) first = i;
  keep.push_back(open[first]);
  while (keep.size() < static_cast<std::size_t>(std::max(1, count)) && keep.size() < open.size()) {
    std::size_t best = 0;
    double best_d = -1.0;
    for (std::size_t i = 0; i < open.size(); ++i) {
      double nearest = 4.0;
      for (const auto& q : keep) nearest = std::min(nearest, (open[i] - q).squaredNorm());
      if (nearest > best_d) best_d = nearest, best = i;
    }
    if (best_d <= 1e-12) break;
    keep.push_back(open[best]);
  }
  return keep;
}

}  // namespace

std::vector<Eigen::Vector3d> cap_directions(double cap_rad, int count) {
  std::vector<Eigen::Vector3d> local;
  for (int i = 0; i < count; ++i) {
    const double cz = 1.0 - (1.0 - std::cos(cap_rad)) * (i + 0.5) / count;
    const double sz = std::sqrt(std::max(0.0, 1.0 - cz * cz));
    const double az = i * std::numbers::pi * (3.0 - std::sqrt(5.0));
    local.emplace_back(sz * std::cos(az), sz * std::sin(az), cz);
  }
  return local;
}

std::vector<Viewpoint> open_direction_viewpoints(const RoughModel& rough, const OcclusionScene& scene,
                                                 const SensorModel& sensor, const ModelSpec& spec,
                                                 const ViewpointSettings& st, const std::vector<std::uint32_t>& rows,
                                                 std::size_t max_rows, std::size_t* targeted_rows) {
  if (rows.empty() || max_rows == 0) {
    if (targeted_rows) *targeted_rows = 0;
    return {};
  }
  const std::vector<std::uint32_t> targets = spread_targets(rough, sensor, rows, max_rows);
  if (targeted_rows) *targeted_rows = targets.size();

  const double r_near = sensor.optimal_standoff_mm * st.standoff_factor;
  // Not all the way to the precision limit: views there comply only at normal incidence and verify poorly.
  const double r_far = std::max(r_near, std::min(sensor.range_max_mm, max_range_for_precision_mm(sensor, spec)) * 0.8);
  const int levels = std::max(1, st.open_direction_standoffs);
  // Probe directions within the stricter grazing limit of the normal.
  const std::vector<Eigen::Vector3d> local = cap_directions(0.9 * std::min(sensor.grazing_xz_rad, sensor.grazing_yz_rad), 96);
  const double eps = 0.01 * rough.mean_edge_mm + 1e-3;

  std::vector<std::vector<Viewpoint>> per_row(targets.size());
  const RoughPointTree tree(rough);
  tbb::parallel_for(std::size_t{0}, targets.size(), [&](std::size_t k) {
    const Eigen::Vector3d p = rough.points[targets[k]], n = rough.normals[targets[k]];
    if (n.squaredNorm() < 0.5) return;
    const Eigen::Quaterniond to_n = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), n);
    std::vector<Eigen::Vector3d> open;
    for (const auto& l : local) {
      const Eigen::Vector3d d = to_n * l;
      if (!scene.first_hit(p + eps * n, d, kOffSurfaceStart * eps, r_far)) open.push_back(d);
    }
    if (open.empty()) return;
    for (const auto& d : spread_directions(open, n, st.open_directions_per_row))
      for (int s = 0; s < levels; ++s) {
        const double standoff = levels == 1 ? r_near : r_near + (r_far - r_near) * s / (levels - 1);
        const Eigen::Vector3d position = p + standoff * d;
        if (!keeps_clearance(rough, tree, position, st.clearance_mm)) continue;
        const double scan = design_scan_length_mm(sensor, spec, standoff, st.scan_length_design_incidence_rad);
        const double tilt = 0.5 * std::atan2(sensor.baseline_mm, standoff);
        for (int level = 0; level < st.twist_levels; ++level) {
          Viewpoint v;
          v.position = position;
          v.axis = -d;
          v.twist_rad = kTwoPi * level / st.twist_levels;
          v.standoff_mm = standoff;
          v.scan_length_mm = scan;
          v.target_row = static_cast<std::int32_t>(targets[k]);
          v.twist_level = level;
          per_row[k].push_back(v);
          if (st.bisector_tilt) {
            // Laser and receiver rays straddling the open direction: both fit a narrow opening.
            const Viewpoint t = bisector_twin(v, p, standoff, tilt);
            if (keeps_clearance(rough, tree, t.position, st.clearance_mm)) per_row[k].push_back(t);
          }
        }
      }
  });
  std::vector<Viewpoint> out;
  for (auto& v : per_row) out.insert(out.end(), v.begin(), v.end());
  return out;
}

std::vector<Viewpoint> single_best_views(const RoughModel& rough, const std::vector<std::uint32_t>& rows,
                                         const SensorModel& sensor, const ModelSpec& spec, int twist_levels,
                                         double standoff_factor) {
  if (rows.empty()) return {};
  if (twist_levels < 1) throw ConfigError("single best view: twist_levels must be >= 1");
  Eigen::Vector3d mean_n = Eigen::Vector3d::Zero(), centroid = Eigen::Vector3d::Zero();
  double area = 0.0;
  for (auto r : rows) {
    mean_n += rough.area_mm2[r] * rough.normals[r];
    centroid += rough.area_mm2[r] * rough.points[r];
    area += rough.area_mm2[r];
  }
  if (mean_n.norm() == 0.0 || area == 0.0) return {};
  mean_n.normalize();
  centroid /= area;
  // Centre vertex: the segment row nearest the area centroid.
  std::uint32_t centre = rows.front();
  for (auto r : rows)
    if ((rough.points[r] - centroid).squaredNorm() < (rough.points[centre] - centroid).squaredNorm()) centre = r;
  const Eigen::Vector3d s = rough.points[centre];
  const Eigen::Vector3d axis = -mean_n;
  std::vector<Viewpoint> out;
  for (int level = 0; level < twist_levels; ++level) {
    const double twist = kTwoPi * level / twist_levels;
    const Eigen::Matrix3d r = camera_rotation(axis, twist);
    // Extent of the segment in the camera frame at zero stand-off (camera at s).
    double half_x = 0.0, half_y = 0.0, rise = 0.0;
    for (auto i : rows) {
      const Eigen::Vector3d p = r.transpose() * (rough.points[i] - s);
      half_x = std::max(half_x, std::abs(p.x()));
      half_y = std::max(half_y, std::abs(p.y()));
      rise = std::max(rise, p.z());  // towards the camera
    }
    // Stand-off so the fan covers ±half_x at the nearest point, and R_min is respected.
    const double fit = half_x / std::tan(0.5 * sensor.fov_x_rad) + rise;
    const double standoff = std::max(sensor.optimal_standoff_mm + rise, fit) * standoff_factor;
    Viewpoint v;
    v.axis = axis;
    v.twist_rad = twist;
    v.position = s - standoff * axis;
    v.standoff_mm = standoff;
    v.scan_length_mm = std::clamp(2.0 * half_y, sensor.scan_length_min_mm, sensor.scan_length_max_mm);
    if (sensor.kind == SensorKind::line_scan) {
      // Never longer than the density spec allows at this range (normal incidence).
      const double cap = design_scan_length_mm(sensor, spec, standoff, 0.0);
      v.scan_length_mm = std::min(v.scan_length_mm, cap);
    }
    v.target_row = static_cast<std::int32_t>(centre);
    v.twist_level = level;
    out.push_back(v);
  }
  return out;
}

}  // namespace scancell::planner
