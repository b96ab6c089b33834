#include "planner/core/cell_viewpoints.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>

#include <Eigen/Geometry>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace scancell::planner {
namespace {

/// The steepest elevation the tilt axis allows (tilt 0 looks horizontally; tilt φ looks down by φ).
double max_elevation(const CellModel& cell) {
  const Axis& tilt = cell.axes[cell.axis_index("tilt")];
  return std::min(std::abs(tilt.min), std::abs(tilt.max));
}

/// The camera frame (object coordinates) looking along `b` with the cell's one twist: camera y = −(Z × b)
/// normalised in the table frame, so that the table can turn it onto world +Y with the camera on the
/// scanner's side; x = y × z.
Eigen::Matrix3d cell_frame(const Eigen::Vector3d& b_table, const Eigen::Matrix3d& table_to_object) {
  const Eigen::Vector3d y = -Eigen::Vector3d::UnitZ().cross(b_table).normalized();
  const Eigen::Vector3d z = -b_table;
  Eigen::Matrix3d r;
  r.col(0) = y.cross(z);
  r.col(1) = y;
  r.col(2) = z;
  return table_to_object * r;
}

/// `b` (table frame) with its elevation set to `elev` and its azimuth turned by `yaw` about the table axis.
Eigen::Vector3d aim(const Eigen::Vector3d& b, double elev, double yaw) {
  Eigen::Vector2d h = b.head<2>();
  if (h.norm() < 1e-9) h = Eigen::Vector2d(-1.0, 0.0);  // straight down or up: any azimuth, take one
  h.normalize();
  const double c = std::cos(yaw), s = std::sin(yaw);
  const Eigen::Vector2d hr(c * h.x() - s * h.y(), s * h.x() + c * h.y());
  return Eigen::Vector3d(hr.x() * std::cos(elev), hr.y() * std::cos(elev), std::sin(elev));
}

/// A view found clear: its viewpoint (stand-off set) and the stand-off step it took (0: as seeded).
struct Placed {
  Viewpoint view;
  int step = 0;
};

/// The first of `steps` stand-offs, from `seed_standoff` out to `range_cap`, at which the view aimed at
/// `target` with rotation `rotation(standoff)` and scan length `scan_length(standoff, step, rotation)` is reachable
/// with the scanner body clear; `reachable` is set when the axes reached any of them. The body's collision
/// does not depend on the axes, so it is tested first: on the arm every inverse kinematics is a numerical
/// solve, and colliding stand-offs are solved only to tell "colliding" from "unreachable" when none is kept.
template <class Rotation, class ScanLength>
std::optional<Placed> first_clear_standoff(const CellModel& cell, const CollisionChecker& checker, const Eigen::Vector3d& target,
                                           double seed_standoff, double range_cap, int steps, Rotation rotation,
                                           ScanLength scan_length, bool& reachable) {
  struct Pose {
    Eigen::Isometry3d pose;
    double scan;
  };
  std::vector<Pose> colliding;
  for (int step = 0; step < std::max(1, steps); ++step) {
    const double standoff = steps <= 1 ? seed_standoff : seed_standoff + (range_cap - seed_standoff) * step / (steps - 1);
    if (step > 0 && standoff <= seed_standoff) break;
    const Eigen::Matrix3d r = rotation(standoff);
    const Eigen::Vector3d b = -r.col(2);
    const double scan = scan_length(standoff, step, r);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = r;
    pose.translation() = target - standoff * b;
    if (checker.collides(pose, scan)) {
      colliding.push_back({pose, scan});
      continue;
    }
    if (!inverse_kinematics(cell, pose, scan).ok) continue;
    reachable = true;
    Placed out{viewpoint_from_pose(r, pose.translation(), scan), step};
    out.view.standoff_mm = standoff;
    return out;
  }
  for (const auto& c : colliding)
    if (!reachable && inverse_kinematics(cell, c.pose, c.scan).ok) reachable = true;
  return std::nullopt;
}

}  // namespace

bool has_cell_native_viewpoints(const CellModel& cell) {
  return cell.kinematics == CellKinematics::turntable_lift_tilt || cell.kinematics == CellKinematics::arm_turntable;
}

namespace {

/// How far `p_table` (table frame) lies above the top of the highest table fixture under it (the plate), mm;
/// nothing when no fixture lies under it or the point is not above the fixture's top.
std::optional<double> height_over_table_fixture(const CellModel& cell, const Eigen::Vector3d& p_table) {
  std::optional<double> top;
  for (const auto& f : cell.fixtures) {
    if (!f.on_table || (p_table.head<2>().array() < f.box.min.head<2>().array()).any() ||
        (p_table.head<2>().array() > f.box.max.head<2>().array()).any())
      continue;
    if (!top || f.box.max.z() > *top) top = f.box.max.z();
  }
  if (!top || p_table.z() <= *top) return std::nullopt;
  return p_table.z() - *top;
}

/// The steepest upward elevation of a view `standoff_mm` from a target `over_plate_mm` above the plate's top
/// (height_over_table_fixture) whose camera stands no lower than that top: its sight line stays above the plate.
double plate_height_elevation(double over_plate_mm, double standoff_mm) {
  return std::asin(std::clamp(over_plate_mm / standoff_mm, -1.0, 1.0));
}

/// arm_turntable: the wrist takes any twist, so every free candidate (each twist and bisector tilt of each
/// optimal-zone position) is a pose the cell may take as it is. Where the arm cannot reach it or the scanner
/// body would hit the object or the plate, it steps back along its boresight towards the precision-limited
/// range; a view looking up at a face turned to the plate, when no stand-off works, is lowered by
/// `cell_oblique_rad` towards the horizontal about the target (the plate blocks the view from below).
std::vector<Viewpoint> arm_viewpoints(const std::vector<Viewpoint>& seeds, const SensorModel& sensor,
                                      const ModelSpec& spec, const ViewpointSettings& st, const CellModel& cell,
                                      const CollisionChecker& checker, CellGenerationReport& rep) {
  const double range_cap = std::min(sensor.range_max_mm, max_range_for_precision_mm(sensor, spec));
  const Eigen::Matrix3d object_to_table = cell.object_on_table.linear();
  struct Out {
    std::optional<Viewpoint> view;
    bool stepped = false, lowered = false, reachable = false;
  };
  std::vector<Out> per(seeds.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, seeds.size(), 16), [&](const auto& range) {
    for (std::size_t k = range.begin(); k != range.end(); ++k) {
      const Viewpoint& seed = seeds[k];
      const Eigen::Vector3d target = seed.position + seed.standoff_mm * seed.axis;
      // The seed's own rotation, then (looking up) the same lowered towards the horizontal by cell_oblique_rad;
      // either lowered further where its camera would stand below the top of the plate under the target (it
      // would look through the plate: as turntable views, capped where the camera stays at the plate's height).
      const Eigen::Vector3d b_table = object_to_table * seed.axis;
      const double elev = std::asin(std::clamp(b_table.z(), -1.0, 1.0));
      const auto over_plate = height_over_table_fixture(cell, cell.object_on_table * target);
      auto lowering_at = [&](double lowering, double standoff) {
        return over_plate ? std::max(lowering, elev - plate_height_elevation(*over_plate, standoff)) : lowering;
      };
      std::vector<double> lowerings = {0.0};
      if (b_table.z() > std::sin(st.cell_oblique_rad) && lowering_at(st.cell_oblique_rad, seed.standoff_mm) != lowering_at(0.0, seed.standoff_mm))
        lowerings.push_back(st.cell_oblique_rad);
      // Turning by a positive angle about Z × b lowers b (about b × Z, as before session 43, raised it: the
      // "lowered" view looked up more steeply still).
      Eigen::Vector3d about = Eigen::Vector3d::Zero();
      if (b_table.head<2>().norm() > 1e-9)
        about = object_to_table.transpose() * Eigen::Vector3d::UnitZ().cross(b_table).normalized();
      auto rotation_at = [&](double lowering, double standoff) -> Eigen::Matrix3d {
        const double by = lowering_at(lowering, standoff);
        if (by <= 0.0 || about.isZero()) return seed.rotation();
        return Eigen::AngleAxisd(by, about).toRotationMatrix() * seed.rotation();
      };
      Out& o = per[k];
      for (std::size_t n = 0; n < lowerings.size() && !o.view; ++n) {
        const auto placed = first_clear_standoff(
            cell, checker, target, seed.standoff_mm, range_cap, st.cell_standoff_steps,
            [&](double standoff) { return rotation_at(lowerings[n], standoff); },
            [&](double standoff, int step, const Eigen::Matrix3d&) {
              return step == 0 ? seed.scan_length_mm : design_scan_length_mm(sensor, spec, standoff, st.scan_length_design_incidence_rad);
            },
            o.reachable);
        if (!placed) continue;
        Viewpoint v = placed->view;
        v.target_row = seed.target_row;
        v.twist_level = seed.twist_level;
        v.tilt_rad = seed.tilt_rad;
        o.view = v;
        o.lowered = lowering_at(lowerings[n], v.standoff_mm) > lowerings[n];
        o.stepped = placed->step > 0 || n > 0 || o.lowered;
      }
    }
  });
  std::vector<Viewpoint> out;
  for (const auto& o : per) {
    if (o.view) {
      out.push_back(*o.view);
      rep.stepped_back += o.stepped;
      rep.lowered += o.lowered;
    } else {
      ++(o.reachable ? rep.colliding : rep.unreachable);
    }
  }
  return out;
}

}  // namespace

namespace {

/// What the expansion of aim points gives: the views kept, and why the others were not.
struct Expanded {
  std::vector<Viewpoint> views;
  std::size_t clamped = 0, stepped_back = 0, lowered = 0, unreachable = 0, colliding = 0;
};

/// turntable_lift_tilt: the five views of one aim point (the thesis' view along its normal with the elevation
/// clamped to the tilt range, the bisector pair, the two oblique views), each at its first clear stand-off.
Expanded expand_aim(const AimPoint& a, const SensorModel& sensor, const ModelSpec& spec, const ViewpointSettings& st,
                    const CellModel& cell, const CollisionChecker& checker) {
  const Eigen::Matrix3d object_to_table = cell.object_on_table.linear();
  const Eigen::Matrix3d table_to_object = object_to_table.transpose();
  const double elev_max = max_elevation(cell);
  const double range_cap = std::min(sensor.range_max_mm, max_range_for_precision_mm(sensor, spec));
  Expanded o;
  Eigen::Vector3d b0 = object_to_table * (-a.normal);
  const double elev0 = std::asin(std::clamp(b0.z(), -1.0, 1.0));
  const double elev_c = std::clamp(elev0, -elev_max, elev_max);
  if (elev_c != elev0) {
    ++o.clamped;
    // A face steeper than the tilt allows says little about the azimuth to view it from; look inwards
    // from the rim side, where the radial axis has the most room (it cannot reach over the table's centre).
    const Eigen::Vector3d p_table = cell.object_on_table * a.point;
    if (p_table.head<2>().norm() > 1e-6) b0.head<2>() = -p_table.head<2>().normalized() * b0.head<2>().norm();
  }
  // The oblique pair: the elevation raised and lowered, both inside the tilt range (one side twice as far
  // when the other would leave it).
  double up = elev_c + st.cell_oblique_rad, down = elev_c - st.cell_oblique_rad;
  if (up > elev_max) up = elev_c - 2.0 * st.cell_oblique_rad;
  if (down < -elev_max) down = elev_c + 2.0 * st.cell_oblique_rad;
  // A view looking up from below the plate's top at a point above it looks through the plate: a face turned
  // to the plate is seen from the side instead, its elevation capped where the camera stays at the plate's
  // height (then the sight line stays above the plate), at the cost of incidence (eq. 3.4's grazing limits
  // decide whether that still measures it). Variants the cap makes one are tried once.
  const auto over_plate = height_over_table_fixture(cell, cell.object_on_table * a.point);
  auto elevation_at = [&](double elev, double standoff) {
    return over_plate ? std::min(elev, plate_height_elevation(*over_plate, standoff)) : elev;
  };
  // (elevation, yaw sign): the thesis' view, the bisector pair, the two oblique views.
  const std::pair<double, int> variants[] = {{elev_c, 0}, {elev_c, 1}, {elev_c, -1}, {up, 0}, {down, 0}};
  std::vector<std::pair<double, int>> tried;
  int variant = -1;
  for (const auto& [elev_raw, yaw_sign] : variants) {
    ++variant;
    const double elev = std::clamp(elev_raw, -elev_max, elev_max);
    const std::pair<double, int> at_seed{elevation_at(elev, a.standoff_mm), yaw_sign};
    if (std::any_of(tried.begin(), tried.end(), [&](const auto& t) { return std::abs(t.first - at_seed.first) < 1e-9 && t.second == at_seed.second; }))
      continue;
    tried.push_back(at_seed);
    bool reachable = false;
    // The bisector's yaw is half the triangulation angle at the stand-off tried.
    auto yaw_at = [&](double standoff) { return yaw_sign * 0.5 * std::atan2(sensor.baseline_mm, standoff); };
    // The sweep keeps eq. 3.8 at the aim as this view sees it: a clamped or capped elevation sees it obliquely.
    const auto placed = first_clear_standoff(
        cell, checker, a.point, a.standoff_mm, range_cap, st.cell_standoff_steps,
        [&](double standoff) { return cell_frame(aim(b0, elevation_at(elev, standoff), yaw_at(standoff)), table_to_object); },
        [&](double standoff, int, const Eigen::Matrix3d& r) {
          return aimed_scan_length_mm(sensor, spec, standoff, r, a.normal, st.scan_length_design_incidence_rad);
        },
        reachable);
    if (placed) {
      Viewpoint v = placed->view;
      v.target_row = a.row;
      v.twist_level = variant;
      v.tilt_rad = yaw_at(v.standoff_mm);
      o.views.push_back(v);
      o.stepped_back += placed->step > 0;
      o.lowered += elevation_at(elev, v.standoff_mm) < elev;
    } else {
      ++(reachable ? o.colliding : o.unreachable);
    }
  }
  return o;
}

/// turntable_lift_tilt: every aim point expanded (expand_aim), in order; parallel over the aims.
std::vector<Viewpoint> turntable_viewpoints(const std::vector<AimPoint>& aims, const SensorModel& sensor, const ModelSpec& spec,
                                            const ViewpointSettings& st, const CellModel& cell, const CollisionChecker& checker,
                                            CellGenerationReport& rep) {
  std::vector<Expanded> per(aims.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, aims.size(), 8), [&](const auto& range) {
    for (std::size_t k = range.begin(); k != range.end(); ++k) per[k] = expand_aim(aims[k], sensor, spec, st, cell, checker);
  });
  std::vector<Viewpoint> out;
  for (auto& o : per) {
    rep.clamped += o.clamped;
    rep.stepped_back += o.stepped_back;
    rep.lowered += o.lowered;
    rep.unreachable += o.unreachable;
    rep.colliding += o.colliding;
    out.insert(out.end(), o.views.begin(), o.views.end());
  }
  return out;
}

}  // namespace

std::vector<Viewpoint> cell_viewpoints(const RoughModel& rough, const std::vector<Viewpoint>& seeds,
                                       const SensorModel& sensor, const ModelSpec& spec,
                                       const ViewpointSettings& st, const CellModel& cell,
                                       const CollisionChecker& checker, CellGenerationReport* report) {
  CellGenerationReport rep;
  if (cell.kinematics == CellKinematics::arm_turntable) {
    rep.seeds = seeds.size();
    std::vector<Viewpoint> out = arm_viewpoints(seeds, sensor, spec, st, cell, checker, rep);
    rep.candidates = out.size();
    if (report) *report = rep;
    return out;
  }
  // One seed per optimal-zone position: the untilted, first-twist free candidate of each target row, aimed at
  // the row with its stand-off.
  std::vector<AimPoint> aims;
  {
    std::map<std::int32_t, const Viewpoint*> by_row;
    for (const auto& v : seeds)
      if (v.target_row >= 0 && v.tilt_rad == 0.0) by_row.emplace(v.target_row, &v);
    for (const auto& [row, v] : by_row)
      aims.push_back({rough.points[static_cast<std::uint32_t>(row)], rough.normals[static_cast<std::uint32_t>(row)], v->standoff_mm, row});
  }
  rep.seeds = aims.size();
  std::vector<Viewpoint> out = turntable_viewpoints(aims, sensor, spec, st, cell, checker, rep);
  rep.candidates = out.size();
  if (report) *report = rep;
  return out;
}

std::vector<Viewpoint> cell_viewpoints_at(const std::vector<AimPoint>& aims, const SensorModel& sensor, const ModelSpec& spec,
                                          const ViewpointSettings& st, const CellModel& cell, const CollisionChecker& checker,
                                          CellGenerationReport* report) {
  CellGenerationReport rep;
  rep.seeds = aims.size();
  std::vector<Viewpoint> out;
  if (cell.kinematics == CellKinematics::arm_turntable) {
    // The arm takes any twist: the free views along each normal, every twist level, then stepped back or
    // lowered where the arm needs it (arm_viewpoints).
    std::vector<Viewpoint> free;
    for (const auto& a : aims)
      for (int level = 0; level < std::max(1, st.twist_levels); ++level) {
        Viewpoint v;
        v.position = a.point + a.standoff_mm * a.normal;
        v.axis = -a.normal;
        v.twist_rad = 2.0 * std::numbers::pi * level / std::max(1, st.twist_levels);
        v.standoff_mm = a.standoff_mm;
        v.scan_length_mm = design_scan_length_mm(sensor, spec, a.standoff_mm, st.scan_length_design_incidence_rad);
        v.target_row = a.row;
        v.twist_level = level;
        free.push_back(v);
      }
    out = arm_viewpoints(free, sensor, spec, st, cell, checker, rep);
  } else if (cell.kinematics == CellKinematics::turntable_lift_tilt) {
    out = turntable_viewpoints(aims, sensor, spec, st, cell, checker, rep);
  }
  rep.candidates = out.size();
  if (report) *report = rep;
  return out;
}

std::vector<AimPoint> aims_open_to_sensor(const std::vector<AimPoint>& aims, const OcclusionScene& scene, const SensorModel& sensor,
                                          double ray_offset_mm, std::size_t* closed, int probes) {
  if (probes < 1) throw std::invalid_argument("aims_open_to_sensor: probes " + std::to_string(probes) + " (want at least 1)");
  const double cap = std::atan(std::hypot(std::tan(sensor.grazing_xz_rad), std::tan(sensor.grazing_yz_rad)));
  const std::vector<Eigen::Vector3d> local = cap_directions(std::min(cap, 0.5 * std::numbers::pi), probes);
  std::vector<std::uint8_t> open(aims.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, aims.size(), 16), [&](const auto& range) {
    for (std::size_t k = range.begin(); k != range.end(); ++k) {
      if (!(aims[k].normal.squaredNorm() > 1e-12)) {  // no normal to probe around: kept, not judged
        open[k] = 1;
        continue;
      }
      const Eigen::Vector3d n = aims[k].normal.normalized();
      const Eigen::Quaterniond to_n = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), n);
      OcclusionRay ray;
      ray.origin = (aims[k].point + ray_offset_mm * n).cast<float>();
      ray.t_near = static_cast<float>(kOffSurfaceStart * ray_offset_mm);  // unit directions: t in mm
      ray.t_far = static_cast<float>(sensor.range_min_mm);
      for (const auto& l : local) {
        ray.dir = (to_n * l).cast<float>();
        if (!scene.occluded1(ray)) {
          open[k] = 1;
          break;
        }
      }
    }
  });
  std::vector<AimPoint> out;
  for (std::size_t k = 0; k < aims.size(); ++k)
    if (open[k]) out.push_back(aims[k]);
  if (closed) *closed = aims.size() - out.size();
  return out;
}

// Where the rough surface bends (a cleft, a rim by the plate, a crease), the vertex normal is a mean no face has,
// and a view along it sees every face at an angle: with samples judging a row by its faces
// (matrix.footprint_samples) such views finish it (knot1 on the turntable: docs/quality.md).
std::vector<AimPoint> face_aims(const RoughModel& rough, const std::vector<std::uint32_t>& rows, double min_angle_rad, double standoff_mm) {
  constexpr std::size_t kMaxFacesPerRow = 3;
  std::vector<std::vector<std::uint32_t>> incident(rough.size());
  for (std::uint32_t t = 0; t < rough.triangles.size(); ++t)
    for (const auto v : rough.triangles[t]) incident[v].push_back(t);
  const double max_cos = std::cos(min_angle_rad);
  std::vector<AimPoint> out;
  for (const auto r : rows) {
    if (r >= rough.size()) throw std::out_of_range("face_aims: row " + std::to_string(r) + " past the " + std::to_string(rough.size()) + " rows");
    std::vector<Eigen::Vector3d> kept{rough.normals[r]};
    for (const auto t : incident[r]) {
      if (kept.size() > kMaxFacesPerRow) break;
      const auto& tri = rough.triangles[t];
      const Eigen::Vector3d n = (rough.points[tri[1]] - rough.points[tri[0]]).cross(rough.points[tri[2]] - rough.points[tri[0]]);
      if (!(n.norm() > 1e-12)) continue;
      const Eigen::Vector3d u = n.normalized();
      if (std::any_of(kept.begin(), kept.end(), [&](const Eigen::Vector3d& k) { return k.dot(u) > max_cos; })) continue;
      kept.push_back(u);
      const Eigen::Vector3d centroid = (rough.points[tri[0]] + rough.points[tri[1]] + rough.points[tri[2]]) / 3.0;
      out.push_back({rough.points[r] + 0.5 * (centroid - rough.points[r]), u, standoff_mm, static_cast<std::int32_t>(r)});
    }
  }
  return out;
}

}  // namespace scancell::planner
