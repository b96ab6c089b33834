#pragma once
// The cell oracle of issue 15, shared by bench_cell (single-shot plans) and bench_loop (the daemon's closed
// loop): dense candidates made from the fine mesh itself in the same configuration space as the plan, with
// the same reachability, collisions and plate, covered greedily, and judged with the plan by the analytic
// measurability test (frustum, bi-static visibility, eq. 3.4, eq. 3.8) on the fine mesh's vertices, a crease
// vertex by its faces (judge_model).
//
// Oracle (shared/design/QUALITY-TARGETS.md): one view per K-th fine vertex along its normal at f_d·R_o, scan
// length from the density spec; free space: 8 twists; on turntable_lift_tilt the one twist the cell reaches
// (baseline along world +Y, camera on +X), tilt clamped to the tilt axis' range; on arm_turntable free
// space's 8 twists (a wrist takes any); on a cell the axes must reach each and
// the scanner body must clear the fine object and the plate, stepping back along the boresight when not.
//
// In the cell's own space (`cell_space` given, cell-native cells): the same aims also get the views the
// planner's cell-native generator makes of a point (planner/core/cell_viewpoints.hpp, as a replan aims at the
// footprint samples of open rows): on turntable_lift_tilt the bisector pair and the two oblique views beside
// the thesis' view, on arm_turntable every twist stepped back or lowered. The plan's candidates are such views
// of rough-model points; without them the oracle's reach lacks what only a slanted view measures (a bore's
// wall, a face turned to the plate), and the plan's views there count against it. `along_normal` then keeps
// the oracle above (QUALITY-TARGETS.md's), from the same matrix.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "bench_common.hpp"

#include "planner/config.hpp"
#include "planner/core/cell_viewpoints.hpp"
#include "planner/core/cover.hpp"
#include "planner/core/measurability.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/plan.hpp"

namespace scancell::bench {

namespace sp = scancell::planner;

/// The fine model the benches judge by (issue 15's analytic test): the fine mesh's vertices as rows, in its
/// order, except that a vertex on a crease is judged by its faces. There (an adjacent triangle over 40° from
/// the vertex normal: a box's edge, a hole's rim, a fillet's end) the vertex normal is a bisector no surface
/// has: a view square to one face of a box's edge sees it 45° off and may fail eq. 3.4 or 3.8 for it although
/// it measures the face, and a view at 45° passes it while it measures each face at 45°. So a crease vertex
/// keeps its row with no area (the oracle still aims at it), and its area goes to one row per adjacent
/// triangle: a point inside the triangle near the vertex (barycentric 0.6, 0.2, 0.2), the triangle's normal,
/// a third of its area. These rows follow the vertex rows, in the crease vertices' order.
inline sp::RoughModel judge_model(const sp::TriangleMesh& fine_mesh) {
  sp::RoughModel fine = sp::make_rough_model(fine_mesh);
  const std::size_t n = fine.size();
  std::vector<std::uint8_t> on_crease(n, 0);
  for (const auto r : sp::crease_rows(fine, 40.0 * std::numbers::pi / 180.0)) on_crease[r] = 1;
  std::vector<std::vector<std::uint32_t>> faces_of(n);
  for (std::uint32_t t = 0; t < fine.triangles.size(); ++t)
    for (auto v : fine.triangles[t])
      if (on_crease[v]) faces_of[v].push_back(t);
  for (std::uint32_t r = 0; r < n; ++r) {
    if (!on_crease[r] || faces_of[r].empty()) continue;
    fine.area_mm2[r] = 0.0;
    for (const auto t : faces_of[r]) {
      const auto& tri = fine.triangles[t];
      const Eigen::Vector3d fn = (fine.points[tri[1]] - fine.points[tri[0]]).cross(fine.points[tri[2]] - fine.points[tri[0]]);
      if (fn.norm() == 0.0) continue;  // no area, no direction
      Eigen::Vector3d p = 0.6 * fine.points[r];
      for (auto v : tri)
        if (v != r) p += 0.2 * fine.points[v];
      fine.points.push_back(p);
      fine.normals.push_back(fn.normalized());
      fine.area_mm2.push_back(fn.norm() / 6.0);
      if (!fine.segment.empty()) fine.segment.push_back(fine.segment[r]);
      if (!fine.hypothetical.empty()) fine.hypothetical.push_back(fine.hypothetical[r]);
    }
  }
  return fine;
}

/// The oracle's candidates: one per `decimation`-th of the first `aim_rows` fine rows, looking along the normal.
inline std::vector<sp::Viewpoint> oracle_candidates(const sp::RoughModel& fine, const sp::SensorModel& sensor,
                                             const sp::ModelSpec& spec, const sp::CellModel* cell, int decimation,
                                             std::size_t aim_rows) {
  const double standoff = 1.02 * sensor.optimal_standoff_mm;
  const double length = sp::design_scan_length_mm(sensor, spec, standoff, std::numbers::pi / 6);
  std::vector<sp::Viewpoint> out;
  double tilt_max = std::numbers::pi / 2;
  // An arm's wrist takes any twist: its oracle is free space's, then held to what the arm reaches below.
  const bool one_twist = cell && cell->kinematics == sp::CellKinematics::turntable_lift_tilt;
  if (one_twist) {
    const auto& tilt = cell->axes[cell->axis_index("tilt")];
    tilt_max = std::min(std::abs(tilt.min), std::abs(tilt.max));
  }
  for (std::uint32_t i = 0; i < aim_rows; i += decimation) {
    Eigen::Vector3d b = -fine.normals[i];
    if (!one_twist) {
      for (int k = 0; k < 8; ++k) {
        sp::Viewpoint v;
        v.axis = b;
        v.twist_rad = 2 * std::numbers::pi * k / 8;
        v.position = fine.points[i] - b * standoff;
        v.standoff_mm = standoff;
        v.scan_length_mm = length;
        v.target_row = static_cast<std::int32_t>(i);
        out.push_back(v);
      }
      continue;
    }
    // The cell's one twist: the baseline horizontal, the camera on the far side of the boresight's horizontal
    // part; the boresight's elevation clamped to the tilt range.
    Eigen::Vector2d h = b.head<2>();
    if (h.norm() < 1e-9) h = Eigen::Vector2d(-1, 0);
    h.normalize();
    const double elev = std::clamp(std::asin(std::clamp(b.z(), -1.0, 1.0)), -tilt_max, tilt_max);
    b = Eigen::Vector3d(h.x() * std::cos(elev), h.y() * std::cos(elev), std::sin(elev));
    const Eigen::Vector3d y = -Eigen::Vector3d::UnitZ().cross(b).normalized();
    const Eigen::Vector3d z = -b;
    const Eigen::Vector3d x = y.cross(z);
    Eigen::Matrix3d r;
    r.col(0) = x;
    r.col(1) = y;
    r.col(2) = z;
    sp::Viewpoint v = sp::viewpoint_from_pose(r, fine.points[i] - b * standoff, length);
    v.standoff_mm = standoff;
    v.target_row = static_cast<std::int32_t>(i);
    out.push_back(v);
  }
  return out;
}

/// Area-weighted cumulative fraction (of `of_area`) a sequence of columns covers, restricted to `mask` rows.
inline std::vector<double> progression(const sp::MeasurabilityMatrix& m, const std::vector<std::uint32_t>& order,
                                const std::vector<double>& area, const std::vector<std::uint8_t>& mask, double of_area) {
  std::vector<std::uint8_t> got(m.n_rows, 0);
  std::vector<double> out;
  double a = 0.0;
  for (auto j : order) {
    m.columns[j].for_each([&](std::uint32_t r) {
      if (!got[r] && mask[r]) {
        got[r] = 1;
        a += area[r];
      }
    });
    out.push_back(of_area > 0 ? a / of_area : 0.0);
  }
  return out;
}

inline std::size_t views_to(const std::vector<double>& prog, double target) {
  for (std::size_t k = 0; k < prog.size(); ++k)
    if (prog[k] >= target - 1e-9) return k + 1;
  return 0;
}

/// Move + sweep time of views executed in least-travel order from home (their axis targets by IK from home,
/// re-solved along the tour by plan_travel, as the plan's own are).
inline double cell_time_s(const sp::CellModel& cell, const std::vector<sp::Viewpoint>& views) {
  std::vector<sp::JointVector> q;
  std::vector<Eigen::Isometry3d> poses;
  std::vector<double> scan_mm;
  double scan = 0.0;
  for (const auto& v : views) {
    Eigen::Isometry3d pose;
    pose.matrix() = v.transform();
    const auto ik = sp::inverse_kinematics(cell, pose, v.scan_length_mm);
    if (!ik.ok) continue;
    q.push_back(ik.q);
    poses.push_back(pose);
    scan_mm.push_back(v.scan_length_mm);
    scan += sp::scan_time_s(cell, v.scan_length_mm);
  }
  if (q.empty()) return scan;
  return sp::plan_travel(cell, poses, scan_mm, std::move(q), cell.home()).move_s + scan;
}


/// What the oracle reaches and needs, and what the cell can never reach by cause (fractions of the fine
/// model's whole area). The causes are counted on the views along the normals as aimed, one restriction after
/// another; what the views stepped back along the boresight and the cell's own views (bisector, oblique) reach
/// besides is `regained`, so reachable() = 1 − lost_range − lost_plate − lost_axes − lost_collision + regained.
struct CellOracle {
  std::vector<std::uint8_t> reach;  // fine rows some oracle candidate measures
  double reach_area_mm2 = 0.0, total_area_mm2 = 0.0;
  double lost_range = 0.0, lost_plate = 0.0, lost_axes = 0.0, lost_collision = 0.0, regained = 0.0;
  std::size_t views_95 = 0, views_99 = 0, views_999 = 0;  // greedy views to 95/99/99.9 % of the reach
  std::size_t views_995 = 0;  // and to 99.5 %, the closed loop's completeness target (issue 15)
  std::vector<double> progression;                         // share of the reach after each greedy view
  double cell_time_s = std::nan("");                       // its views to 99 %, travel-ordered (cells only)
  double reachable() const { return total_area_mm2 > 0 ? reach_area_mm2 / total_area_mm2 : 0.0; }
};

/// The cell's own views (the planner's cell-native generator) of every `decimation`-th of the first `aim_rows`
/// fine rows along its normal, at f_d·R_o; reachable and clear of `checker`'s object and fixtures.
inline std::vector<sp::Viewpoint> cell_space_candidates(const sp::RoughModel& fine, const sp::SensorModel& sensor,
                                                        const sp::ModelSpec& spec, const sp::CellModel& cell,
                                                        const sp::CollisionChecker& checker, const sp::ViewpointSettings& vs,
                                                        int decimation, std::size_t aim_rows) {
  std::vector<sp::AimPoint> aims;
  for (std::uint32_t i = 0; i < aim_rows; i += decimation)
    if (fine.normals[i].squaredNorm() > 0.5)  // a knife edge's zero normal says nothing about where to look from
      aims.push_back({fine.points[i], fine.normals[i], 1.02 * sensor.optimal_standoff_mm, static_cast<std::int32_t>(i)});
  return sp::cell_viewpoints_at(aims, sensor, spec, vs, cell, checker);
}

/// The cell's own space the oracles search (cell_oracle's `cell_space`): the shipped planner settings'
/// viewpoints, whatever settings the plan under test was made with, so that comparing two settings keeps one
/// yardstick.
inline const sp::ViewpointSettings& shipped_cell_space() {
  static const sp::ViewpointSettings vs =
      sp::load_planner_settings(shipped_settings_path()).viewpoints;
  return vs;
}

/// The oracle for the fine model `fine` (judge_model of `fine_mesh`) in `scene` (the fine mesh and, on a cell, the
/// plate), on the placed `cell` or in free space; with `cell_space` on a cell-native cell, in the cell's own
/// space (above), and then `along_normal` (when given) is the oracle of the views along the normals alone.
inline CellOracle cell_oracle(const sp::TriangleMesh& fine_mesh, const sp::RoughModel& fine, const sp::OcclusionScene& scene,
                              const sp::SensorModel& sensor, const sp::ModelSpec& spec, const sp::CellModel* cell,
                              int decimation, const sp::ViewpointSettings* cell_space = nullptr,
                              CellOracle* along_normal = nullptr) {
  // The aims: the fine vertices (judge_model's crease rows after them are judged, not aimed at).
  const std::size_t aim_rows = std::min(fine.size(), fine_mesh.vertices.size());
  std::vector<sp::Viewpoint> cands = oracle_candidates(fine, sensor, spec, cell, decimation, aim_rows);
  const std::size_t n_base = cands.size();
  std::vector<std::uint8_t> usable(n_base, 1), axis_ok(n_base, 1);
  std::size_t n_normal = n_base;  // the views along the normals, stepped back ones included
  if (cell) {
    const sp::CollisionChecker checker(*cell, fine_mesh);
    const double cap = std::min(sensor.range_max_mm, sp::max_range_for_precision_mm(sensor, spec));
    std::vector<sp::Viewpoint> stepped;
    for (std::size_t i = 0; i < n_base; ++i) {
      Eigen::Isometry3d pose;
      pose.matrix() = cands[i].transform();
      const Eigen::Vector3d target = cands[i].position + cands[i].standoff_mm * cands[i].axis;
      axis_ok[i] = sp::inverse_kinematics(*cell, pose, cands[i].scan_length_mm).ok;
      if (axis_ok[i] && !checker.collides(pose, cands[i].scan_length_mm)) continue;
      usable[i] = 0;
      for (double d : {0.5 * (cands[i].standoff_mm + cap), cap}) {
        sp::Viewpoint v = cands[i];
        v.standoff_mm = d;
        v.position = target - d * v.axis;
        v.scan_length_mm = sp::design_scan_length_mm(sensor, spec, d, std::numbers::pi / 6);
        pose.matrix() = v.transform();
        if (sp::inverse_kinematics(*cell, pose, v.scan_length_mm).ok && !checker.collides(pose, v.scan_length_mm)) {
          stepped.push_back(v);
          break;
        }
      }
    }
    cands.insert(cands.end(), stepped.begin(), stepped.end());
    n_normal = cands.size();
    usable.resize(n_normal, 1);  // a view stepped back was kept because the axes reach it clear of collision
    axis_ok.resize(n_normal, 1);
    if (cell_space && sp::has_cell_native_viewpoints(*cell)) {
      // Poses the views along the normals already hold (on the arm, most: its own space starts from the
      // same eight twists) are not evaluated twice.
      std::set<std::array<long long, 12>> seen;
      for (std::size_t i = 0; i < cands.size(); ++i)
        if (usable[i]) seen.insert(cands[i].pose_key());
      for (const auto& v : cell_space_candidates(fine, sensor, spec, *cell, checker, *cell_space, decimation, aim_rows))
        if (seen.insert(v.pose_key()).second) cands.push_back(v);
    }
    usable.resize(cands.size(), 1);
    axis_ok.resize(cands.size(), 1);
  }
  const auto all_m = sp::build_measurability(fine, scene, sensor, spec, cands);
  // Reach before each restriction: no plate, plate, axis ranges, collisions (= the oracle's reach).
  auto area_of = [&](const std::vector<std::uint8_t>& got) {
    double a = 0.0;
    for (std::size_t r = 0; r < fine.size(); ++r) a += got[r] ? fine.area_mm2[r] : 0.0;
    return a;
  };
  std::vector<std::uint8_t> reach_noplate(fine.size(), 0), reach_plate(fine.size(), 0), reach_axes(fine.size(), 0);
  if (cell) {
    const sp::OcclusionScene bare(fine_mesh);
    std::vector<sp::Viewpoint> base(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(n_base));
    const auto nm = sp::build_measurability(fine, bare, sensor, spec, base);
    for (const auto& c : nm.columns) c.for_each([&](std::uint32_t r) { reach_noplate[r] = 1; });
  }
  std::vector<std::uint8_t> reach_as_aimed(fine.size(), 0);  // the views along the normals that the cell takes as aimed
  for (std::size_t i = 0; i < n_base; ++i) {
    all_m.columns[i].for_each([&](std::uint32_t r) { reach_plate[r] = 1; });
    if (axis_ok[i]) all_m.columns[i].for_each([&](std::uint32_t r) { reach_axes[r] = 1; });
    if (usable[i]) all_m.columns[i].for_each([&](std::uint32_t r) { reach_as_aimed[r] = 1; });
  }
  // The oracle of the usable candidates before `limit`: its reach, what is lost by cause, its greedy cover.
  auto oracle_of = [&](std::size_t limit) {
    sp::MeasurabilityMatrix om;
    om.n_rows = all_m.n_rows;
    std::vector<std::size_t> om_cand;
    for (std::size_t i = 0; i < limit; ++i)
      if (usable[i]) {
        om.columns.push_back(all_m.columns[i]);
        om_cand.push_back(i);
      }
    CellOracle o;
    o.reach.assign(fine.size(), 0);
    for (const auto& c : om.columns) c.for_each([&](std::uint32_t r) { o.reach[r] = 1; });
    o.reach_area_mm2 = area_of(o.reach);
    o.total_area_mm2 = fine.total_area_mm2;
    const double total = o.total_area_mm2;
    o.lost_range = cell ? 1.0 - area_of(reach_noplate) / total : 1.0 - area_of(reach_plate) / total;
    o.lost_plate = cell ? (area_of(reach_noplate) - area_of(reach_plate)) / total : 0.0;
    o.lost_axes = (area_of(reach_plate) - area_of(reach_axes)) / total;
    o.lost_collision = (area_of(reach_axes) - area_of(reach_as_aimed)) / total;
    o.regained = (o.reach_area_mm2 - area_of(reach_as_aimed)) / total;
    sp::CoverSettings cs;
    cs.mode = sp::CoverMode::greedy;
    cs.eliminate_redundant = false;
    const auto oc = sp::greedy_cover(om, fine.area_mm2, cs);
    const auto oprog = progression(om, oc.views, fine.area_mm2, o.reach, o.reach_area_mm2);
    o.views_95 = views_to(oprog, 0.95);
    o.views_99 = views_to(oprog, 0.99);
    o.views_999 = views_to(oprog, 0.999);
    o.views_995 = views_to(oprog, 0.995);
    o.progression = oprog;
    if (cell) {
      std::vector<sp::Viewpoint> ov;
      for (std::size_t k = 0; k < std::min<std::size_t>(o.views_99 ? o.views_99 : oc.views.size(), oc.views.size()); ++k)
        ov.push_back(cands[om_cand[oc.views[k]]]);
      o.cell_time_s = cell_time_s(*cell, ov);
    }
    return o;
  };
  CellOracle full = oracle_of(cands.size());
  if (along_normal) *along_normal = n_normal < cands.size() ? oracle_of(n_normal) : full;
  return full;
}

/// The share of the oracle's reach that `views` measure by the analytic test on the fine rows.
inline double mv_of_reach(const sp::RoughModel& fine, const sp::OcclusionScene& scene, const sp::SensorModel& sensor,
                          const sp::ModelSpec& spec, const std::vector<sp::Viewpoint>& views, const CellOracle& o) {
  if (views.empty() || o.reach_area_mm2 <= 0.0) return 0.0;
  const auto m = sp::build_measurability(fine, scene, sensor, spec, views);
  std::vector<std::uint32_t> all(views.size());
  for (std::uint32_t k = 0; k < all.size(); ++k) all[k] = k;
  return progression(m, all, fine.area_mm2, o.reach, o.reach_area_mm2).back();
}

}  // namespace scancell::bench
