#include "planner/plan.hpp"
#include "common/json_matrix.hpp"
#include "common/timing.hpp"
#include "planner/kinematics/resting_poses.hpp"

#include "planner/core/cell_viewpoints.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "common/errors.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <array>
#include <map>
#include <memory>
#include <set>
#include <numbers>
#include <sstream>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace scancell::planner {
namespace {

using Clock = std::chrono::steady_clock;

nlohmann::json vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

/// Greedy's cover, made smaller by the local search when it finds a smaller registered cover of the same rows
/// (local_cover.hpp); the views are then ordered as greedy would take them.
void improve_by_local_search(const MeasurabilityMatrix& m, const std::vector<double>& w, ViewPlan& p) {
  const CoverSettings& st = p.settings.cover;
  if (st.local_search_iterations == 0 || p.cover.views.size() < 2) return;
  const auto better = local_search_cover(m, w, st, p.cover.views, st.local_search_iterations,
                                         st.local_search_time_limit_s, p.settings.seed, &p.local_search);
  if (better.size() >= p.cover.views.size()) return;
  CoverResult re = describe_cover(m, w, st, order_by_gain(m, w, st, better));
  re.blocked_by_registration = p.cover.blocked_by_registration;
  re.bridge_views = p.cover.bridge_views;
  re.redundant_removed = p.cover.redundant_removed;
  re.stop_reason = p.cover.stop_reason + "; local search: " + std::to_string(p.cover.views.size()) + " -> " +
                   std::to_string(better.size()) + " views";
  p.cover = std::move(re);
}

}  // namespace

nlohmann::json placement_to_json(const PlacementChoice& c) {
  using nlohmann::json;
  json options = json::array();
  for (const auto& o : c.options) {
    const json rot = row_major_json(o.object_to_table);
    options.push_back({{"resting_pose", o.pose < 0 ? json(nullptr) : json(o.pose + 1)},
                       {"as_given", o.as_given},
                       {"object_to_table_row_major", rot},
                       {"probability", o.probability},
                       {"tip_angle_rad", o.tip_angle_rad},
                       {"estimated_coverage", o.estimated_coverage},
                       {"views", o.views},
                       {"cell_time_s", o.cell_time_s},
                       {"settles_in_pose", o.settles_on < 0 ? json(nullptr) : json(o.settles_on + 1)},
                       {"settle_angle_rad", o.settle_angle_rad},
                       {"plan_time_s", o.plan_s}});
  }
  json poses = json::array();
  for (const auto& r : c.rest.poses)
    poses.push_back({{"down_object", {r.down_object.x(), r.down_object.y(), r.down_object.z()}},
                     {"probability", r.probability},
                     {"tip_angle_rad", r.tip_angle_rad},
                     {"margin_mm", r.margin_mm},
                     {"com_height_mm", r.com_height_mm},
                     {"support_area_mm2", r.support_area_mm2}});
  return {{"chosen", c.chosen + 1},
          {"reason", c.reason},
          {"centre_of_mass_mm", {c.rest.centre_of_mass.x(), c.rest.centre_of_mass.y(), c.rest.centre_of_mass.z()}},
          {"centre_of_mass_of", c.rest.solid ? "volume" : "surface"},
          {"hull_faces", c.rest.hull_faces},
          {"resting_poses", poses},
          {"options", options}};
}

namespace {

/// The inputs every stage of one plan reads, beside the plan it fills.
struct Stage {
  ViewPlan& p;
  const SensorModel& sensor;
  const ModelSpec& spec;
  const PlannerSettings& settings;                   // as applied: countermeasures merged
  const std::vector<std::uint8_t>* measured_rows;    // replans: rows already measured
  const std::atomic<int>* cancel;
  const CollisionChecker* checker;                   // with a cell
  const RowFootprints* footprints;                   // replans: what the open rows lack (footprint.hpp)
};

/// Free space: the margin against the rough model's own error (config.hpp), merged field by field, the larger.
Countermeasures with_free_space_margin(Countermeasures cm, const Countermeasures& f) {
  cm.frustum_detune = std::max(cm.frustum_detune, f.frustum_detune);
  cm.dof_margin_mm = std::max(cm.dof_margin_mm, f.dof_margin_mm);
  cm.compliance_buffer = std::max(cm.compliance_buffer, f.compliance_buffer);
  cm.visibility_margin_mm = std::max(cm.visibility_margin_mm, f.visibility_margin_mm);
  return cm;
}

/// Free space: the guard against the rough model's own error (config.hpp), chosen once per plan. On a cell
/// the single shot is predicted by footprint samples whatever the rough model, and never by the margin.
/// - None where the rows are the object's own dense mesh: a mesh taken as given (not decimated) whose rows
///   lie closer together than twice the visibility margin already probes, with its neighbours' own rays,
///   the ±margin around each row, and its normals are the object's. Measured (docs/quality.md): the bunny as
///   given (37.7k rows, 1.3 mm apart) plans 45 views at verified m_v 1.000 without the margin against 57 with
///   it, in a third of the time; the bunny at 26k rows plans in 9.3 s, 11.8 s with whole-row samples.
/// - Footprint samples (matrix.footprint_samples) on a rough model free of noise (the object's mesh,
///   decimated or coarse): it is wrong only at its own resolution, where the surface a row stands for bends
///   away from its vertex normal. The samples test that surface where it is, each by its triangle's normal,
///   and leave the rows the rough model gets right (flat faces) at the spec (session 41: free space 717 ->
///   537 views, m_v of the reach >= 0.99 on 10 of 10 either way; knot1 as given, 3.2k rows 5.5 mm apart,
///   104 views at verified m_v 0.9935 against the margin's 140 at 0.9997).
/// - The margin (matrix.free_space_countermeasures) on a rough model that carries noise
///   (RoughModelOptions::normal_noise_mm, thesis 5.4, or surface_error_mm), or with footprint_samples 0. Noise tilts the
///   triangles too, at random, which samples cannot model: bench_quality's σ_rm rough models lose up to 0.02
///   of verified m_v (knot1) by samples alone, and samples with the margin cost 12 % more views for at most
///   +0.005.
void choose_free_space_guard(ViewPlan& p, PlannerSettings& settings) {
  const Countermeasures& f = settings.free_space_countermeasures;
  const double spacing_mm = p.rough.size() ? std::sqrt(p.rough.total_area_mm2 / static_cast<double>(p.rough.size())) : 0.0;
  if (!p.rough_report.decimated && spacing_mm <= 2.0 * f.visibility_margin_mm) return;  // the object's own dense mesh
  if (settings.footprint_samples > 0 && !rough_model_carries_error(p.rough_options)) {
    p.free_space_guard = FreeSpaceGuard::kFootprintSamples;
  } else if (f.any()) {
    p.free_space_guard = FreeSpaceGuard::kMargin;
    settings.matrix.countermeasures = with_free_space_margin(settings.matrix.countermeasures, f);
  }
}

/// The cover's row weights: the rows' areas, zero for rows already measured (the cover goes after the rest),
/// scaled by the closed loop's factors.
std::vector<double> row_weights(const RoughModel& rough, const std::vector<std::uint8_t>* measured_rows,
                                const std::vector<double>* row_weight_scale) {
  if (measured_rows && measured_rows->size() != rough.size())
    throw DataError("replan: " + std::to_string(measured_rows->size()) + " measured-row flags for a rough model of " +
                    std::to_string(rough.size()) + " rows (not the rough model the views were measured on)");
  std::vector<double> w = rough.area_mm2;
  if (measured_rows)
    for (std::size_t r = 0; r < w.size(); ++r)
      if ((*measured_rows)[r]) w[r] = 0.0;
  if (row_weight_scale) {
    if (row_weight_scale->size() != rough.size())
      throw DataError("replan: " + std::to_string(row_weight_scale->size()) + " row weight factors for a rough model of " +
                      std::to_string(rough.size()) + " rows");
    for (std::size_t r = 0; r < w.size(); ++r) w[r] *= std::clamp((*row_weight_scale)[r], 0.0, 1.0);
  }
  return w;
}

/// Rows already measured leave every column.
void strip_measured(MeasurabilityMatrix& m, const std::vector<std::uint8_t>* measured_rows) {
  if (!measured_rows) return;
  for (auto& c : m.columns) {
    std::vector<std::uint32_t> keep;
    c.for_each([&](std::uint32_t r) {
      if (!(*measured_rows)[r]) keep.push_back(r);
    });
    c = MeasurabilityColumn(std::move(keep), m.n_rows);
  }
}

/// With a cell: every candidate becomes the nearest pose the cell can reach (thesis 6.3.2) and is then
/// evaluated at that pose; unreachable and colliding ones are dropped.
void fit_to_cell(const Stage& s, std::vector<Viewpoint>& cands) {
  ViewPlan& p = s.p;
  if (!p.cell) return;
  std::vector<std::uint8_t> fate(cands.size(), 0);  // 0 kept as is, 1 moved, 2 unreachable, 3 collides
  tbb::parallel_for(std::size_t{0}, cands.size(), [&](std::size_t i) {
    Viewpoint& v = cands[i];
    Eigen::Isometry3d desired;
    desired.matrix() = v.transform();
    const auto reach = nearest_reachable(*p.cell, desired, v.scan_length_mm);
    if (!reach) {
      fate[i] = 2;
      return;
    }
    if (!reach->isApprox(desired, 1e-12)) {
      Viewpoint moved = viewpoint_from_pose(reach->linear(), reach->translation(), v.scan_length_mm);
      moved.standoff_mm = v.standoff_mm;
      moved.target_row = v.target_row;
      moved.twist_level = v.twist_level;
      moved.source = v.source;
      moved.tilt_rad = v.tilt_rad;
      v = moved;
      fate[i] = 1;
    }
    if (s.checker->collides(*reach, v.scan_length_mm)) fate[i] = 3;
  });
  std::vector<Viewpoint> kept;
  for (std::size_t i = 0; i < cands.size(); ++i) {
    p.cell_report.moved += fate[i] == 1;
    p.cell_report.unreachable += fate[i] == 2;
    p.cell_report.colliding += fate[i] == 3;
    if (fate[i] < 2) kept.push_back(cands[i]);
  }
  cands = std::move(kept);
}

/// Poses that coincide (twists that collapse to one reachable pose, seeds that expand alike) are one column.
void merge_duplicates(ViewPlan& p, std::vector<Viewpoint>& cands) {
  if (!p.cell) return;
  std::vector<Viewpoint> kept;
  std::set<std::array<long long, 12>> seen;
  for (std::size_t i = 0; i < cands.size(); ++i) {
    if (!seen.insert(cands[i].pose_key()).second) {
      ++p.cell_report.duplicates;
      continue;
    }
    kept.push_back(cands[i]);
  }
  cands = std::move(kept);
}

/// The candidate viewpoints (thesis ch. 6): the optimal scanning zone, the segments' single-best views, and
/// with a cell either its own space (cell_viewpoints.hpp) or the free ones projected onto it.
std::vector<Viewpoint> make_candidates(const Stage& s, const OcclusionScene& scene) {
  ViewPlan& p = s.p;
  ViewpointSettings vs = s.settings.viewpoints;
  if (!p.cell) vs.min_position_spacing_fraction = vs.free_space_min_position_spacing_fraction;
  auto candidates = generate_viewpoints(p.rough, scene, s.sensor, s.spec, vs, &p.generation);
  const std::size_t n_zone = candidates.size();  // the optimal-zone candidates (single-best views follow)
  // Thesis 6.3.4: with a segmented rough model, each segment also gets its single-best-view candidates
  // (twist in 90° steps); the cover takes them when one view can do a whole patch.
  if (!p.rough.segment.empty()) {
    std::map<int, std::vector<std::uint32_t>> rows_of;
    for (std::uint32_t i = 0; i < p.rough.size(); ++i)
      if (p.rough.segment[i] >= 0) rows_of[p.rough.segment[i]].push_back(i);
    for (const auto& [label, rows] : rows_of) {
      auto sbv = single_best_views(p.rough, rows, s.sensor, s.spec, 4, s.settings.viewpoints.standoff_factor);
      for (Viewpoint& v : sbv) v.source = ViewSource::single_best;
      candidates.insert(candidates.end(), sbv.begin(), sbv.end());
      p.generation.single_best_views += sbv.size();
    }
    p.segments = rows_of.size();
  }
  if (p.cell && s.settings.viewpoints.cell_native && has_cell_native_viewpoints(*p.cell)) {
    // The cell's own space: each optimal-zone position expanded into the views this cell can take of it
    // (cell_viewpoints.hpp); the single-best views of segments are projected as before.
    std::vector<Viewpoint> segment_views(candidates.begin() + static_cast<std::ptrdiff_t>(n_zone), candidates.end());
    candidates.resize(n_zone);
    std::vector<Viewpoint> native = cell_viewpoints(p.rough, candidates, s.sensor, s.spec, s.settings.viewpoints, *p.cell,
                                                    *s.checker, &p.cell_generation);
    fit_to_cell(s, segment_views);
    native.insert(native.end(), segment_views.begin(), segment_views.end());
    if (s.footprints) {
      // A replan also aims at what each open row lacks, not only at rough-model rows: the sample of its
      // unfilled cells nearest their middle, along that sample's normal (the cell oracle aims at fine
      // vertices so, and reaches rows no candidate of the optimal zone finishes).
      // Those closed to every view are dropped as the rows' own aims are (make_matrix).
      CellGenerationReport aimed;
      const std::vector<AimPoint> open =
          aims_open_to_sensor(footprint_aims(*s.footprints, s.sensor.optimal_standoff_mm * vs.standoff_factor), scene, s.sensor,
                              ray_offset_mm(p.rough, s.settings.matrix), &p.cell_generation.footprint_aims_closed);
      std::vector<Viewpoint> at = cell_viewpoints_at(open, s.sensor, s.spec, s.settings.viewpoints, *p.cell, *s.checker, &aimed);
      for (Viewpoint& v : at) v.source = ViewSource::footprint_aim;
      native.insert(native.end(), at.begin(), at.end());
      p.cell_generation.footprint_aims = aimed.seeds;
      p.cell_generation.footprint_candidates = aimed.candidates;
    }
    candidates = std::move(native);
  } else {
    fit_to_cell(s, candidates);
  }
  merge_duplicates(p, candidates);
  return candidates;
}

/// The rows no column of `m` measures, less those already measured.
std::vector<std::uint32_t> open_rows_nothing_measures(const MeasurabilityMatrix& m, const std::vector<std::uint8_t>* measured_rows) {
  std::vector<std::uint32_t> rows = m.unmeasurable_rows();
  if (measured_rows) std::erase_if(rows, [&](std::uint32_t r) { return (*measured_rows)[r] != 0; });
  return rows;
}

/// Candidates added after the first matrix: their columns (tested against `spec`, measured rows stripped)
/// appended to `matrix`, the views to `candidates`, their pairs and rays to the plan's matrix statistics. With
/// a `margin`, the columns are tested under those countermeasures; and `margin_only_where_alone`, only on the
/// rows no column of `matrix` measures, the others by the matrix's own test, both from one pass (PlainElements).
void append_candidates(const Stage& s, const OcclusionScene& scene, const ModelSpec& spec, std::vector<Viewpoint> extra,
                       MeasurabilityMatrix& matrix, std::vector<Viewpoint>& candidates,
                       const std::optional<Countermeasures>& margin = std::nullopt, bool margin_only_where_alone = false) {
  ViewPlan& p = s.p;
  MatrixStats st;
  MatrixSettings ms = s.settings.matrix;
  if (margin) ms.countermeasures = *margin;
  const bool margin_where_alone = margin && margin_only_where_alone;
  std::vector<std::uint8_t> others;  // rows a column of `matrix` measures
  PlainElements plain{s.settings.matrix.countermeasures, {}, &others};
  if (margin_where_alone) {
    others.assign(matrix.n_rows, 0);
    for (const auto& c : matrix.columns) c.for_each([&](std::uint32_t r) { others[r] = 1; });
  }
  auto more = build_measurability(p.rough, scene, s.sensor, spec, extra, ms, &st, s.cancel, margin_where_alone ? &plain : nullptr);
  if (margin_where_alone) {
    for (std::size_t j = 0; j < more.columns.size(); ++j) {
      if (plain.matrix.columns[j].count() == 0) continue;
      std::vector<std::uint32_t> rows = more.columns[j].rows();
      const std::vector<std::uint32_t> add = plain.matrix.columns[j].rows();  // only rows of `others`
      rows.insert(rows.end(), add.begin(), add.end());
      std::sort(rows.begin(), rows.end());
      more.columns[j] = MeasurabilityColumn(std::move(rows), more.n_rows);
    }
  }
  strip_measured(more, s.measured_rows);
  candidates.insert(candidates.end(), extra.begin(), extra.end());
  for (auto& c : more.columns) matrix.columns.push_back(std::move(c));
  p.matrix_stats.pairs_total += st.pairs_total;
  p.matrix_stats.pairs_block_culled += st.pairs_block_culled;
  p.matrix_stats.pairs_normal_culled += st.pairs_normal_culled;
  p.matrix_stats.pairs_in_frustum += st.pairs_in_frustum;
  p.matrix_stats.pairs_surviving += st.pairs_surviving;
  p.matrix_stats.pairs_compliant += st.pairs_compliant;
  p.matrix_stats.rays_cast += st.rays_cast;
  p.matrix_stats.pairs_measurable += st.pairs_measurable;
}

/// M for the candidates (thesis 3.3), with the free-space margin's fallback for the rows it would lose, the
/// measured rows stripped, and open-direction views appended (to `candidates` too) for rows nothing measures.
MeasurabilityMatrix make_matrix(const Stage& s, const OcclusionScene& scene, const Countermeasures& plain_cm,
                                std::vector<Viewpoint>& candidates) {
  ViewPlan& p = s.p;
  // With the free-space margin, the plain test's elements come from the same pass: the margin chooses among
  // the views that can measure a row; it does not give up a row only views at the edge of the spec reach (a
  // bore's wall, seen only at grazing incidence): such rows keep the elements the plain test gives them.
  PlainElements plain{plain_cm, {}};
  auto matrix = build_measurability(p.rough, scene, s.sensor, s.spec, candidates, s.settings.matrix, &p.matrix_stats,
                                    s.cancel, p.free_space_guard == FreeSpaceGuard::kMargin ? &plain : nullptr);
  if (p.free_space_guard == FreeSpaceGuard::kMargin) p.generation.rows_without_margin = keep_plain_elements_of_lost_rows(matrix, plain);
  strip_measured(matrix, s.measured_rows);
  // Rows nothing measures get more views: on a cell-native cell first the cell's views of themselves, then
  // (any cell, or free space) views along their open directions (deep holes, undercuts).
  std::vector<std::uint32_t> unmeasurable = open_rows_nothing_measures(matrix, s.measured_rows);
  p.generation.rows_unmeasurable_before = unmeasurable.size();
  const bool native = p.cell && s.settings.viewpoints.cell_native && has_cell_native_viewpoints(*p.cell);
  if (native && !unmeasurable.empty()) {
    // The optimal zone aims at every d_v-th row only, and a row between aims in a cleft or by the plate is
    // open only to a view aimed at it, along its own normal or slanted (the cell oracle aims at every 4th
    // fine vertex so). knot1 on the turntable: the area no candidate reached fell from 2.2 % of the oracle's
    // reach to 0.9 % (docs/quality.md). On the arm too since its inverse kinematics stops stalled solves
    // early (the box's plan took 45 s with these views, 15 s since; docs/quality.md).
    std::vector<AimPoint> aims;
    const double standoff = s.sensor.optimal_standoff_mm * s.settings.viewpoints.standoff_factor;
    for (auto r : unmeasurable)
      if (p.rough.normals[r].squaredNorm() > 0.5) aims.push_back({p.rough.points[r], p.rough.normals[r], standoff, static_cast<std::int32_t>(r)});
    if (s.settings.viewpoints.cell_face_aim_min_angle_rad > 0.0)
      for (const AimPoint& a : face_aims(p.rough, unmeasurable, s.settings.viewpoints.cell_face_aim_min_angle_rad, standoff)) aims.push_back(a);
    // Rows resting on the plate or at the floor of a slot have no view at all: their aims are dropped before
    // their five views each are tested (couplingdown on the turntable: 2,329 aims -> 1,013; with face aims
    // 4,714 -> 1,689 and plan 3.5 -> 2.9 s, the same views measuring the same rows; docs/quality.md).
    std::size_t closed = 0;
    aims = aims_open_to_sensor(aims, scene, s.sensor, ray_offset_mm(p.rough, s.settings.matrix), &closed);
    CellGenerationReport self;
    std::vector<Viewpoint> own = cell_viewpoints_at(aims, s.sensor, s.spec, s.settings.viewpoints, *p.cell, *s.checker, &self);
    for (Viewpoint& v : own) v.source = ViewSource::self_aim;
    merge_duplicates(p, own);
    p.cell_generation.self_aims = self.seeds;
    p.cell_generation.self_aims_closed = closed;
    p.cell_generation.self_candidates = own.size();
    append_candidates(s, scene, s.spec, std::move(own), matrix, candidates);
    unmeasurable = open_rows_nothing_measures(matrix, s.measured_rows);
  }
  if (!s.settings.viewpoints.open_direction_views || unmeasurable.empty()) return matrix;
  const std::size_t max_rows =
      std::max<std::size_t>(16, p.rough.size() / static_cast<std::size_t>(std::max(1, s.settings.viewpoints.position_decimation)));
  // Projected onto a cell (thesis 6.3.2): expanded in the cell's own space instead (each open direction an aim,
  // bisector and oblique, stepped back only when colliding), they measured less on the turntable (knot1 0.9693
  // -> 0.9658 of the oracle's reach, rotor 0.9814 -> 0.9748, cow 0.9825 -> 0.9772): the free views' three
  // stand-offs out to 0.8 of the precision limit see further into a cleft than the nearest clear one.
  std::vector<Viewpoint> extra = open_direction_viewpoints(p.rough, scene, s.sensor, s.spec, s.settings.viewpoints, unmeasurable,
                                                           max_rows, &p.generation.open_direction_rows);
  for (Viewpoint& v : extra) v.source = ViewSource::open_direction;
  fit_to_cell(s, extra);
  merge_duplicates(p, extra);
  p.generation.open_direction_candidates = extra.size();
  // These views work far out, near the precision and density limits, where a rough model's averaged
  // normals make the estimate least reliable: on the rows nothing else measures (what they were made for: a
  // hole's floor, an undercut) their columns claim only rows measured with a margin (open_direction_margin; 10 %
  // was the best of 0, 10 and 25 % in bench_quality). On a noise-free rough model, a row other views measure
  // too they claim by the plain test, as those views do: held to the margin there as well, a far view's
  // outer-wall rows near the density limit were left to views of their own (the tube on the turntable: 5 of
  // its 30 views the fine surface did not need; docs/quality.md, sessions 46-47). A rough model with noise
  // (σ_rm, thesis 5.4) or a rough scan's fused surface keeps the margin on every row: tilted normals are what
  // the margin is for, and without it bench_quality's noisy tube verified 0.9954 -> 0.8394.
  append_candidates(s, scene, s.spec, std::move(extra), matrix, candidates, open_direction_margin(s.settings.matrix.countermeasures),
                    !rough_model_carries_error(p.rough_options));
  return matrix;
}

/// Axis targets of the candidates `which` (every one when null), for costs and travel (IK seeded at home, so
/// deterministic); the others, and all without a cell, stay empty.
std::vector<JointVector> axis_targets(const ViewPlan& p, const std::vector<Viewpoint>& candidates,
                                      const std::vector<std::uint32_t>* which = nullptr) {
  std::vector<JointVector> q_of;
  if (!p.cell) return q_of;
  q_of.resize(candidates.size());
  const std::size_t n = which ? which->size() : candidates.size();
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t k) {
    const std::size_t i = which ? (*which)[k] : k;
    Eigen::Isometry3d pose;
    pose.matrix() = candidates[i].transform();
    const auto ik = inverse_kinematics(*p.cell, pose, candidates[i].scan_length_mm);
    q_of[i] = ik.ok ? ik.q : p.cell->home();
  });
  return q_of;
}

/// The cover (thesis ch. 4): exact (CBC) when asked, else constrained greedy improved by the local search;
/// with a cell, then ordered for the least travel from home, with each view's move and scan time. The axis
/// targets (inverse kinematics) of every candidate only for exact cover's costs, else of the chosen views: on
/// arm_turntable each was a numerical IK solve, and 27k of them took 1.7-1.9 s of a 5k-row plan (fandisk, cow);
/// the shipped arm is solved in closed form since (kinematics/arm_ik.hpp), an arm of another geometry is not.
void choose_cover(ViewPlan& p, const MeasurabilityMatrix& matrix, const std::vector<double>& row_weight,
                  const std::vector<Viewpoint>& candidates) {
  std::vector<JointVector> q_of;
  if (p.settings.cover.mode == CoverMode::exact) {
    q_of = axis_targets(p, candidates);
    // With a cell, c_j is the view's expected time: its scan plus half the move from home (a view is entered
    // and left, each roughly half-way across the envelope).
    std::vector<double> cost;
    if (p.cell)
      for (std::size_t i = 0; i < candidates.size(); ++i)
        cost.push_back(scan_time_s(*p.cell, candidates[i].scan_length_mm) + 0.5 * move_time_s(*p.cell, p.cell->home(), q_of[i]) +
                       1e-3);
    // Started from the default cover (constrained greedy improved by the local search), so exact mode is never
    // worse than it: from greedy alone CBC's 10 s ended above it on large instances (knot1: 152 against 140).
    // Greedy is the one exact cover would run itself (handed over, not run twice).
    const CoverResult greedy = greedy_cover(matrix, row_weight, exact_greedy_settings(p.settings.cover));
    p.cover = greedy;
    improve_by_local_search(matrix, row_weight, p);
    const std::size_t start_views = p.cover.views.size();
    p.cover = exact_cover(matrix, row_weight, p.settings.cover, cost, &p.exact, p.cover.views, &greedy);
    if (p.exact.start_objective > 0.0)
      p.cover.stop_reason += "; started from the local search's " + std::to_string(start_views) + " views";
    p.exact_used = true;
  } else {
    p.cover = greedy_cover(matrix, row_weight, p.settings.cover);
    improve_by_local_search(matrix, row_weight, p);
  }
  if (!p.cell || p.cover.views.empty()) return;
  if (q_of.empty()) q_of = axis_targets(p, candidates, &p.cover.views);
  // Execute in the order that minimises travel from home, each view solved from the one before it (the
  // table's turn, the arm's branch); the cumulative figures follow that order.
  std::vector<JointVector> targets;
  std::vector<Eigen::Isometry3d> poses;
  std::vector<double> scan_mm;
  for (auto j : p.cover.views) {
    targets.push_back(q_of[j]);
    poses.emplace_back(candidates[j].transform());
    scan_mm.push_back(candidates[j].scan_length_mm);
  }
  const Travel travel = plan_travel(*p.cell, poses, scan_mm, std::move(targets), p.cell->home());
  std::vector<std::uint32_t> ordered;
  for (auto k : travel.order) {
    ordered.push_back(p.cover.views[k]);
    q_of[p.cover.views[k]] = travel.targets[k];
  }
  CoverResult re = describe_cover(matrix, row_weight, p.settings.cover, ordered);
  re.blocked_by_registration = p.cover.blocked_by_registration;
  re.bridge_views = p.cover.bridge_views;
  re.redundant_removed = p.cover.redundant_removed;
  re.stop_reason = p.cover.stop_reason;
  p.cover = re;
  JointVector at = p.cell->home();
  for (auto j : p.cover.views) {
    p.view_axes.push_back(q_of[j]);
    p.view_move_s.push_back(move_time_s(*p.cell, at, q_of[j]));
    p.view_scan_s.push_back(scan_time_s(*p.cell, candidates[j].scan_length_mm));
    p.cell_report.travel_s += p.view_move_s.back();
    p.cell_report.scan_s += p.view_scan_s.back();
    at = q_of[j];
  }
}

/// The chosen views, the rows each is predicted to measure (not yet measured) and the predicted gain.
void record_views(ViewPlan& p, const MeasurabilityMatrix& matrix, const std::vector<Viewpoint>& candidates,
                  const std::vector<std::uint8_t>* measured_rows) {
  for (auto j : p.cover.views) p.views.push_back(candidates[j]);
  std::vector<std::uint8_t> predicted(p.rough.size(), 0);
  for (auto j : p.cover.views) {
    std::vector<std::uint32_t>& rows = p.view_rows.emplace_back();
    matrix.columns[j].for_each([&](std::uint32_t r) {
      predicted[r] = 1;
      if (!(measured_rows && (*measured_rows)[r])) rows.push_back(r);
    });
  }
  for (std::uint32_t r = 0; r < predicted.size(); ++r)
    if (predicted[r] && !(measured_rows && (*measured_rows)[r])) {
      p.predicted_rows.push_back(r);
      p.predicted_gain_mm2 += p.rough.area_mm2[r];
    }
}

/// record_views for a cover over footprint samples (footprint.hpp): a footprint row is predicted when the
/// chosen views together measure enough of its samples, and each view is said to measure the predicted rows it
/// contributes samples to. Rows the candidates cannot measure are the rough model's rows: a footprint row
/// whose samples no candidate measures, not its samples.
void record_views_by_samples(ViewPlan& p, const SampleCover& c, const RowFootprints& f, const std::vector<Viewpoint>& candidates,
                             const std::vector<std::uint8_t>* measured_rows) {
  const std::vector<std::uint8_t> finished = finished_rows(c, f, p.cover.views);
  std::vector<std::uint8_t> predicted(p.rough.size(), 0);
  for (auto j : p.cover.views) {
    p.views.push_back(candidates[j]);
    std::vector<std::uint32_t>& rows = p.view_rows.emplace_back();
    for (auto r : column_rows(c, f, j, finished))
      if (!(measured_rows && (*measured_rows)[r])) {
        rows.push_back(r);
        predicted[r] = 1;
      }
  }
  for (std::uint32_t r = 0; r < predicted.size(); ++r)
    if (predicted[r]) {
      p.predicted_rows.push_back(r);
      p.predicted_gain_mm2 += p.rough.area_mm2[r];
    }
  // The cover lists the rows of its own matrix that no column holds: every footprint row (its samples stand
  // in for it) and the samples no candidate measures. A footprint row is unmeasurable when fewer of its
  // samples than it needs are left: no set of views can finish it (a row of the plate-facing bottom whose
  // footprint reaches a sliver of the side is not measured by the side's views).
  std::vector<std::uint32_t> unseen(f.size(), 0), unmeasurable;
  for (auto r : p.cover.unmeasurable_rows) {
    if (r >= c.n_rows) ++unseen[c.owner[r - c.n_rows]];
    else if (!std::binary_search(f.rows.begin(), f.rows.end(), r)) unmeasurable.push_back(r);
  }
  for (std::size_t k = 0; k < f.size(); ++k)
    if (f.first[k + 1] - f.first[k] - unseen[k] < f.needed[k]) unmeasurable.push_back(f.rows[k]);
  std::sort(unmeasurable.begin(), unmeasurable.end());
  p.cover.unmeasurable_rows = unmeasurable;
}

}  // namespace

ViewPlan plan_views(TriangleMesh object_mm, const SensorModel& sensor, const ModelSpec& spec,
                    const PlannerSettings& settings_in, const RoughModelOptions& rough_options, int threads,
                    const CellModel* cell_in, const std::vector<std::uint8_t>* measured_rows,
                    const std::vector<double>* row_weight_scale, const std::atomic<int>* cancel,
                    const RowFootprints* footprints) {
  // A non-zero `cancel` stops planning at the next stage boundary, or inside the matrix build (the long stage).
  auto check = [cancel](const char* stage) {
    if (cancel && cancel->load() != 0) throw PlanCancelled(std::string("planning stopped by request after ") + stage);
  };
  validate(sensor);
  validate(spec);
  // A mesh that lost all its faces (a caller's filter, an empty file read by hand) has nothing to plan for:
  // refused by name rather than planned to no views (FCL only printed a warning for its empty BVH).
  if (object_mm.triangles.empty() || object_mm.vertices.empty())
    throw MeshError("plan: the object mesh has no triangles (" + std::to_string(object_mm.vertices.size()) + " vertices)");
  ViewPlan p;
  PlannerSettings settings = settings_in;
  if (settings.countermeasures_from_cell) {
    if (!cell_in) throw ConfigError("matrix.countermeasures: auto needs a cell (--cell) for its pose-error model");
    settings.matrix.countermeasures = countermeasures_for(sensor, cell_in->pose_error, settings.viewpoints.standoff_factor);
  }
  // Free space: the margin against the rough model's own error (config.hpp). (A dense mesh planned as given
  // needs it least: bunny, 37.7k rows, 58 views with it and 45 without, both verified m_v 1.0000. But coarse
  // meshes given as they are need it as much as decimated ones: knot1's 3.2k rows, 0.982 without; so it is
  // not switched on decimation. docs/quality.md.)
  if (cell_in) {
    // The object rests on the plate in the cell's configured orientation (object_rpy_rad, or the resting pose
    // a placement choice put there): its rotated bounding box centred on the turntable axis, its lowest point
    // on the table top, then the configured offset.
    p.cell = *cell_in;
    p.cell->object_on_table =
        place_on_plate(object_mm, cell_in->object_on_table.linear(), cell_in->object_on_table.translation());
  }
  p.sensor = sensor;
  p.spec = spec;
  p.settings = settings;
  p.settings.cover.coverage_goal = spec.coverage_goal;
  p.rough_options = rough_options;
  p.threads = threads > 0 ? threads : tbb::info::default_concurrency();
  tbb::task_arena arena(p.threads);
  arena.execute([&] {
    auto t = Clock::now();
    p.rough = build_rough_model(std::move(object_mm), rough_options, &p.rough_report);
    p.times.rough_model_s = seconds_since(t);
    check("the rough model");
    if (!cell_in) {
      choose_free_space_guard(p, settings);
      p.settings.matrix.countermeasures = settings.matrix.countermeasures;
    }
    const std::vector<double> row_weight = row_weights(p.rough, measured_rows, row_weight_scale);
    // The rows predicted by footprint samples: a replan's open rows, by what they lack (the caller's measured
    // coverage); or, in a single shot when matrix.footprint_samples says so (on a cell, and in free space
    // where choose_free_space_guard chose them), every row by its whole footprint, but for rows under two samples' worth of area
    // (matrix.footprint_sample_area_mm2), left to their vertex unless on a crease; else the rows on a crease
    // (matrix.crease_footprint_samples). Only a replan's also get candidates aimed at them (the stage's `footprints`): for
    // every row of a single shot those are five more per row, and 13-14 s more of plan for 5k rows
    // (docs/quality.md).
    RowFootprints whole;
    const RowFootprints* predicted_by = footprints;
    bool every_row = false;  // `whole` is a single shot's: rows `matrix` is built for in full
    if (!footprints && !measured_rows) {
      if (settings.footprint_samples > 0 && (p.cell || p.free_space_guard == FreeSpaceGuard::kFootprintSamples)) {
        WholeRowSampling sampling{static_cast<std::size_t>(settings.footprint_samples), settings.footprint_sample_area_mm2, {}, 0};
        if (settings.footprint_sample_area_mm2 > 0.0 && settings.crease_footprint_samples > 0) {
          sampling.crease = crease_rows(p.rough, settings.crease_angle_rad);
          sampling.crease_samples = static_cast<std::size_t>(settings.crease_footprint_samples);
        }
        whole = whole_row_footprints(p.rough, spec, sampling);
        every_row = true;
      } else if (settings.crease_footprint_samples > 0) {
        whole = MeasuredCoverage(p.rough, spec)
                    .open_footprints(crease_rows(p.rough, settings.crease_angle_rad), static_cast<std::size_t>(settings.crease_footprint_samples));
      }
      if (!whole.rows.empty()) predicted_by = &whole;
    }
    p.rows_by_footprint_samples = predicted_by ? predicted_by->size() : 0;
    if (footprints) {
      footprints->validate(static_cast<std::uint32_t>(p.rough.size()));
      for (auto r : footprints->rows)
        if (measured_rows && r < measured_rows->size() && (*measured_rows)[r])
          throw DataError("replan: row " + std::to_string(r) + " has a footprint to predict and is flagged measured");
    }

    t = Clock::now();
    // In a cell the fixtures (the turntable plate) occlude too: the underside of an object on the plate is
    // not measurable, whatever the rough model says.
    const OcclusionScene scene(p.cell ? with_fixtures(p.rough.mesh(), *p.cell) : p.rough.mesh());
    p.times.scene_s = seconds_since(t);

    t = Clock::now();
    std::unique_ptr<CollisionChecker> checker;
    if (p.cell) checker = std::make_unique<CollisionChecker>(*p.cell, p.rough.mesh());
    const Stage stage{p, sensor, spec, settings, measured_rows, cancel, checker.get(), footprints};
    std::vector<Viewpoint> candidates = make_candidates(stage, scene);
    p.candidates = candidates.size();
    p.times.viewpoints_s = seconds_since(t);
    check("viewpoint generation");

    t = Clock::now();
    const MeasurabilityMatrix matrix = make_matrix(stage, scene, settings_in.matrix.countermeasures, candidates);
    std::optional<SampleCover> samples;
    if (predicted_by) {
      const auto t_samples = Clock::now();
      // Every row by samples: each is tested only against the views that measure its row's surroundings (bunny
      // on the turntable, 5k rows: 107 M point tests -> 9 M; 0.8 % of the elements, slivers, lost; docs/quality.md).
      // Crease rows and a replan's rows are tested in full: a few, and a replan's measured neighbours are
      // stripped from `matrix`.
      samples = cover_by_samples(matrix, row_weight, *predicted_by, scene, sensor, spec, candidates, settings.matrix,
                                 p.rough.mean_edge_mm, cancel,
                                 p.free_space_guard == FreeSpaceGuard::kMargin ? &settings_in.matrix.countermeasures : nullptr,
                                 every_row ? &p.rough.triangles : nullptr);
      // Under the between-view constraint (eq. 4.2) two views overlap on a footprint row when each measures
      // some of its samples: counted by samples, a box's edge row no longer lets views of its two faces
      // register, nothing else does at the spec, and the cover stopped with faces unplanned (a 120 x 80 x 40
      // box at 600 rows: 0.26 in free space). The constrained cover, the local search and exact cover all count
      // overlap in them.
      if (registration_applies(settings.cover))
        samples->matrix.overlap = overlap_by_footprint_rows(*samples, *predicted_by, row_weight);
      p.times.matrix_samples_s = seconds_since(t_samples);
    }
    p.candidates = candidates.size();
    p.matrix_density = matrix.density();
    p.matrix_bytes = matrix.memory_bytes();
    p.times.matrix_s = seconds_since(t);
    check("the measurability matrix");

    t = Clock::now();
    if (samples) {
      choose_cover(p, samples->matrix, samples->weight, candidates);
      record_views_by_samples(p, *samples, *predicted_by, candidates, measured_rows);
    } else {
      choose_cover(p, matrix, row_weight, candidates);
      record_views(p, matrix, candidates, measured_rows);
    }
    if (settings.keep_candidates) p.candidate_views = candidates;
    p.times.cover_s = seconds_since(t);
  });
  return p;
}

namespace {

using nlohmann::json;

json sensor_json(const SensorModel& s) {
  return {{"name", s.name},
          {"kind", to_string(s.kind)},
          {"fov_x_rad", s.fov_x_rad},
          {"fov_y_rad", s.fov_y_rad},
          {"scan_length_min_mm", s.scan_length_min_mm},
          {"scan_length_max_mm", s.scan_length_max_mm},
          {"range_min_mm", s.range_min_mm},
          {"range_max_mm", s.range_max_mm},
          {"optimal_standoff_mm", s.optimal_standoff_mm},
          {"baseline_mm", s.baseline_mm},
          {"samples_x", s.samples_x},
          {"samples_y", s.samples_y},
          {"noise", {{"cx", s.noise_cx}, {"cy", s.noise_cy}, {"cz_per_mm", s.noise_cz_per_mm}}},
          {"grazing", {{"t_xz_rad", s.grazing_xz_rad}, {"t_yz_rad", s.grazing_yz_rad}}}};
}

/// The settings as applied (the countermeasures merged: the plan says what its matrix used).
json settings_json(const ViewPlan& p) {
  const auto& vs = p.settings.viewpoints;
  json out = {{"seed", p.settings.seed},
              {"viewpoints",
               {{"scheme", to_string(vs.scheme)},
                {"standoff_factor", vs.standoff_factor},
                {"position_decimation", vs.position_decimation},
                {"min_position_spacing_fraction", vs.min_position_spacing_fraction},
                {"free_space_min_position_spacing_fraction", vs.free_space_min_position_spacing_fraction},
                {"twist_levels", vs.twist_levels},
                {"standoff_adjust_max_mm", vs.standoff_adjust_max_mm},
                {"scan_length_design_incidence_rad", vs.scan_length_design_incidence_rad},
                {"clearance_mm", vs.clearance_mm},
                {"bisector_tilt", vs.bisector_tilt},
                {"open_direction_views", vs.open_direction_views},
                {"open_direction_standoffs", vs.open_direction_standoffs},
                {"open_directions_per_row", vs.open_directions_per_row},
                {"cell_native", vs.cell_native},
                {"cell_oblique_rad", vs.cell_oblique_rad},
                {"cell_standoff_steps", vs.cell_standoff_steps},
                {"cell_face_aim_min_angle_rad", vs.cell_face_aim_min_angle_rad}}},
              {"cover",
               {{"mode", to_string(p.settings.cover.mode)},
                {"registration_threshold", p.settings.cover.registration_threshold},
                {"registration_normalizer", to_string(p.settings.cover.normalizer)},
                {"eliminate_redundant", p.settings.cover.eliminate_redundant},
                {"exact_time_limit_s", p.settings.cover.exact_time_limit_s},
                {"min_view_gain_mm2", p.settings.cover.min_view_gain},
                {"local_search_iterations", p.settings.cover.local_search_iterations},
                {"local_search_stall_work", p.settings.cover.local_search_stall_work},
                {"local_search_time_limit_s", p.settings.cover.local_search_time_limit_s}}},
              {"matrix", {{"ray_offset_mm", p.settings.matrix.ray_offset_mm}, {"footprint_samples", p.settings.footprint_samples},
                          {"footprint_sample_area_mm2", p.settings.footprint_sample_area_mm2},
                          {"crease_footprint_samples", p.settings.crease_footprint_samples},
                          {"crease_angle_rad", p.settings.crease_angle_rad}}}};
  {
    const Countermeasures& cm = p.settings.matrix.countermeasures;
    out["matrix"]["countermeasures"] = {{"frustum_detune", cm.frustum_detune},
                                        {"dof_margin_mm", cm.dof_margin_mm},
                                        {"compliance_buffer", cm.compliance_buffer},
                                        {"visibility_margin_mm", cm.visibility_margin_mm},
                                        {"from_cell_pose_error", p.settings.countermeasures_from_cell},
                                        {"free_space_margin_applied", p.free_space_guard == FreeSpaceGuard::kMargin},
                                        {"free_space_footprint_samples", p.free_space_guard == FreeSpaceGuard::kFootprintSamples}};
  }
  return out;
}

/// The mesh the plan was made for and its rough model.
void object_json(const ViewPlan& p, json& j) {
  Eigen::Matrix4d obj = Eigen::Matrix4d::Identity();
  obj.topLeftCorner<3, 3>() *= p.object.scale;
  const json objt = row_major_json(obj);
  j["object"] = {{"mesh", p.object.mesh_path},
                 {"scale", p.object.scale},
                 {"transform_row_major", objt},
                 {"note", "plan coordinates = mesh coordinates transformed by transform_row_major"},
                 {"file_vertices", p.object.load.file_vertices},
                 {"file_faces", p.object.load.file_faces},
                 {"degenerate_faces_dropped", p.object.load.degenerate_dropped}};
  json rough = {{"vertices", p.rough.size()},
                {"triangles", p.rough.triangles.size()},
                {"area_mm2", p.rough.total_area_mm2},
                {"input_vertices", p.rough_report.input_vertices},
                {"decimated", p.rough_report.decimated},
                {"normal_noise_mm", p.rough_options.normal_noise_mm},
                {"surface_error_mm", p.rough_options.surface_error_mm}};
  if (p.rough_options.target_vertices) rough["target_vertices"] = *p.rough_options.target_vertices;
  if (p.rough_options.rho_rel) rough["rho_rel"] = *p.rough_options.rho_rel;
  j["rough_model"] = rough;
}

json views_json(const ViewPlan& p) {
  json views = json::array();
  for (std::size_t k = 0; k < p.views.size(); ++k) {
    const Viewpoint& v = p.views[k];
    const Eigen::Matrix4d t = v.transform();
    const json tm = row_major_json(t);
    views.push_back({{"index", k},
                     {"camera_to_object_row_major", tm},
                     {"position_mm", vec(v.position)},
                     {"boresight", vec(v.axis)},
                     {"twist_rad", v.twist_rad},
                     {"standoff_mm", v.standoff_mm},
                     {"scan_length_mm", v.scan_length_mm},
                     {"target_row", v.target_row},
                     {"twist_level", v.twist_level},
                     {"tilt_rad", v.tilt_rad},
                     {"source", to_string(v.source)},
                     {"estimated_gain_area_mm2", p.cover.gain_weight[k]},
                     {"cumulative_estimated_measurability", p.cover.cumulative_fraction[k]},
                     {"cumulative_point_fraction", p.cover.cumulative_point_fraction[k]}});
  }
  if (p.cell) {
    for (std::size_t k = 0; k < p.views.size() && k < p.view_axes.size(); ++k) {
      json axes;
      for (std::size_t a = 0; a < p.cell->axes.size(); ++a) axes[p.cell->axes[a].name] = p.view_axes[k][a];
      views[k]["axes"] = axes;
      views[k]["move_time_s"] = p.view_move_s[k];
      views[k]["scan_time_s"] = p.view_scan_s[k];
    }
  }
  return views;
}

json summary_json(const ViewPlan& p) {
  json edges = json::array();
  for (const auto& e : p.cover.registration_edges) edges.push_back({{"a", e.a}, {"b", e.b}, {"sigma", e.sigma}});
  const double est = p.cover.cumulative_fraction.empty() ? 0.0 : p.cover.cumulative_fraction.back();
  const double pts = p.cover.cumulative_point_fraction.empty() ? 0.0 : p.cover.cumulative_point_fraction.back();
  return {
      {"rows_s", p.rough.size()},
      {"candidates_v", p.candidates},
      {"viewpoint_positions", p.generation.positions},
      {"viewpoint_positions_by_decimation", p.generation.positions_by_decimation},
      {"segments", p.segments},
      {"rows_by_footprint_samples", p.rows_by_footprint_samples},
      {"single_best_view_candidates", p.generation.single_best_views},
      {"rows_unmeasurable_by_first_candidates", p.generation.rows_unmeasurable_before},
      {"rows_measured_without_the_free_space_margin", p.generation.rows_without_margin},
      {"open_direction_rows", p.generation.open_direction_rows},
      {"open_direction_candidates", p.generation.open_direction_candidates},
      {"candidates_dropped_inside", p.generation.dropped_inside},
      {"candidates_dropped_clearance", p.generation.dropped_clearance},
      {"matrix_density", p.matrix_density},
      {"matrix_bytes", p.matrix_bytes},
      {"pairs_surviving_culling", p.matrix_stats.pairs_surviving},
      {"rays_cast", p.matrix_stats.rays_cast},
      {"views", p.views.size()},
      {"estimated_measurability", est},
      {"estimated_point_fraction", pts},
      {"measurable_fraction", p.cover.measurable_fraction},
      {"unmeasurable_rows", p.cover.unmeasurable_rows.size()},
      {"stop_reason", p.cover.stop_reason},
      {"bridge_views", p.cover.bridge_views},
      {"redundant_views_removed", p.cover.redundant_removed},
      {"registration",
       {{"threshold", p.settings.cover.registration_threshold},
        {"m_s_rows", p.cover.max_column_count},
        {"m_s_area_mm2", p.cover.max_column_weight},
        {"components", p.cover.registration_components},
        {"connected", p.cover.registration_components <= 1},
        {"edges", edges}}},
      {"times_s",
       {{"rough_model", p.times.rough_model_s},
        {"scene", p.times.scene_s},
        {"viewpoints", p.times.viewpoints_s},
        {"matrix", p.times.matrix_s},
        {"matrix_footprint_samples", p.times.matrix_samples_s},
        {"cover", p.times.cover_s},
        {"total", p.times.total_s()}}},
      {"threads", p.threads}};
}

/// The cell planned for and what it did to the candidates.
void cell_json(const ViewPlan& p, json& j) {
  if (p.cell) {
    const auto& c = *p.cell;
    json axes = json::array();
    for (const auto& a : c.axes)
      axes.push_back({{"name", a.name}, {"type", a.type == AxisType::rotary ? "rotary" : "linear"}, {"home", a.home},
                      {"unit", a.type == AxisType::rotary ? "rad" : "mm"}});
    json fixtures = json::array();
    for (const auto& f : c.fixtures)
      fixtures.push_back({{"name", f.name}, {"frame", "table"},
                          {"min_mm", {f.box.min.x(), f.box.min.y(), f.box.min.z()}},
                          {"max_mm", {f.box.max.x(), f.box.max.y(), f.box.max.z()}}});
    const json place = row_major_json(c.object_on_table.matrix());
    j["cell"] = {{"name", c.name},
                 {"kinematics", c.kinematics == CellKinematics::turntable_lift_tilt ? "turntable_lift_tilt" : "arm_turntable"},
                 {"axes", axes},
                 {"object_on_table_row_major", place},
                 {"fixtures", fixtures},
                 {"pose_error", {{"sigma_p_mm", c.pose_error.sigma_p_mm}, {"sigma_a_rad", c.pose_error.sigma_a_rad}, {"sigma_t_rad", c.pose_error.sigma_t_rad}}}};
    j["summary"]["cell"] = {{"candidates_moved_to_reachable", p.cell_report.moved},
                            {"candidates_unreachable", p.cell_report.unreachable},
                            {"candidates_colliding", p.cell_report.colliding},
                            {"candidates_merged", p.cell_report.duplicates},
                            {"cell_native",
                             {{"seeds", p.cell_generation.seeds},
                              {"candidates", p.cell_generation.candidates},
                              {"elevation_clamped", p.cell_generation.clamped},
                              {"stepped_back", p.cell_generation.stepped_back},
                              {"lowered_to_plate_height", p.cell_generation.lowered},
                              {"unreachable", p.cell_generation.unreachable},
                              {"colliding", p.cell_generation.colliding},
                              {"footprint_aims", p.cell_generation.footprint_aims},
                              {"footprint_aims_closed", p.cell_generation.footprint_aims_closed},
                              {"footprint_candidates", p.cell_generation.footprint_candidates},
                              {"self_aims", p.cell_generation.self_aims},
                              {"self_aims_closed", p.cell_generation.self_aims_closed},
                              {"self_candidates", p.cell_generation.self_candidates}}},
                            {"travel_time_s", p.cell_report.travel_s},
                            {"scan_time_s", p.cell_report.scan_s},
                            {"total_time_s", p.cell_report.travel_s + p.cell_report.scan_s}};
    if (p.placement) j["summary"]["placement"] = placement_to_json(*p.placement);
  }
}

/// The cover's own report: the local search's, or the exact solver's.
void cover_report_json(const ViewPlan& p, json& j) {
  if (p.local_search.start_views > 0) {
    const LocalSearchReport& ls = p.local_search;
    j["summary"]["local_search"] = {{"start_views", ls.start_views},
                                    {"best_views", ls.best_views},
                                    {"iterations", ls.iterations},
                                    {"improvements", ls.improvements},
                                    {"last_improvement_iteration", ls.last_improvement_iteration},
                                    {"work", ls.work},
                                    {"work_at_last_improvement", ls.work_at_last_improvement},
                                    {"rejected_unregistered", ls.rejected_unregistered},
                                    {"time_s", ls.seconds},
                                    // Cut by the clock rather than the swap budget: the cover may depend on the machine.
                                    {"depends_on_machine_speed", ls.time_limit_hit}};
  }
  if (p.exact_used) {
    const ExactReport& e = p.exact;
    j["summary"]["solver"] = {{"name", e.solver},
                              {"status", e.status},
                              {"objective", e.objective},
                              {"bound", e.bound},
                              {"gap", e.gap},
                              {"proven_optimal", e.proven_optimal},
                              // Stopped by the clock: another machine (or load) may return another cover.
                              {"depends_on_machine_speed", !e.proven_optimal && e.status.find("time limit") != std::string::npos},
                              {"lagrangian_bound", e.lagrangian_bound},
                              {"core_columns", e.core_columns},
                              {"greedy_objective", e.greedy_objective},
                              {"time_s", e.seconds},
                              {"solves", e.solves},
                              {"connectivity_cuts", e.connectivity_cuts},
                              {"presolve",
                               {{"rows", e.rows},
                                {"rows_after", e.rows_after_presolve},
                                {"columns", e.columns},
                                {"columns_after", e.columns_after_presolve},
                                {"forced_columns", e.forced_columns},
                                {"merged_rows", e.merged_rows},
                                {"dominated_rows", e.dominated_rows},
                                {"dominated_columns", e.dominated_columns},
                                {"dominance_budget_hit", e.dominance_budget_hit}}}};
  }
}

}  // namespace

nlohmann::json plan_to_json(const ViewPlan& p) {
  json j;
  j["format"] = "scancell-plan";
  j["version"] = 1;
  j["units"] = {{"length", "mm"}, {"angle", "rad"}, {"density", "samples/mm^2"}, {"time", "s"}};
  j["camera_frame"] =
      "x along the laser fan, y along the sweep and baseline (receiver at +y), boresight -z; transform maps camera "
      "to object coordinates";
  j["sensor"] = sensor_json(p.sensor);
  j["spec"] = {{"name", p.spec.name},
               {"precision_mm", p.spec.precision_mm},
               {"density_per_mm2", p.spec.density_per_mm2},
               {"coverage_goal", p.spec.coverage_goal}};
  j["settings"] = settings_json(p);
  object_json(p, j);
  j["views"] = views_json(p);
  j["summary"] = summary_json(p);
  cell_json(p, j);
  cover_report_json(p, j);
  return j;
}

std::string plan_summary(const ViewPlan& p) {
  std::ostringstream os;
  char buf[256];
  const double est = p.cover.cumulative_fraction.empty() ? 0.0 : p.cover.cumulative_fraction.back();
  std::snprintf(buf, sizeof buf, "rough model: %zu vertices (%.0f mm2), candidates: %zu from %zu positions, matrix density %.4f\n",
                p.rough.size(), p.rough.total_area_mm2, p.candidates, p.generation.positions, p.matrix_density);
  os << buf;
  os << " view  standoff_mm  scan_mm  twist_deg  gain_mm2   est_measurability\n";
  for (std::size_t k = 0; k < p.views.size(); ++k) {
    const auto& v = p.views[k];
    std::snprintf(buf, sizeof buf, " %4zu  %11.1f  %7.1f  %9.1f  %8.1f   %.4f\n", k, v.standoff_mm, v.scan_length_mm,
                  v.twist_rad * 180.0 / std::numbers::pi, p.cover.gain_weight[k], p.cover.cumulative_fraction[k]);
    os << buf;
  }
  // The stop reason is free text of any length (a fixed buffer cut it and the newline off): streamed.
  std::snprintf(buf, sizeof buf,
                "views: %zu  estimated measurability: %.4f (area)  reachable: %.4f  unmeasurable rows: %zu  "
                "registration: %s (%zu components, t_r %.2f)  stopped: ",
                p.views.size(), est, p.cover.measurable_fraction, p.cover.unmeasurable_rows.size(),
                // On a cell without the between-view constraint every view registers to the model (a job's
                // cover): the components say how the views overlap, not whether they register.
                p.cover.registration_components <= 1   ? "connected"
                : p.cell && !registration_applies(p.settings.cover) ? "each view to the model"
                                                                    : "NOT connected",
                p.cover.registration_components, p.settings.cover.registration_threshold);
  os << buf << p.cover.stop_reason << "\n";
  if (p.rows_by_footprint_samples > 0) {
    os << "rows predicted by footprint samples: " << p.rows_by_footprint_samples
       << (registration_applies(p.settings.cover) ? " (registration overlap counted by their rows)" : "") << "\n";
  }
  std::snprintf(buf, sizeof buf,
                "times (s): rough %.3f  scene %.3f  viewpoints %.3f  matrix %.3f  cover %.3f  total %.3f  (%d threads)\n",
                p.times.rough_model_s, p.times.scene_s, p.times.viewpoints_s, p.times.matrix_s, p.times.cover_s,
                p.times.total_s(), p.threads);
  os << buf;
  if (p.rows_by_footprint_samples > 0) {
    std::snprintf(buf, sizeof buf, "  of the matrix's %.3f s, %.3f s for the footprint samples\n", p.times.matrix_s, p.times.matrix_samples_s);
    os << buf;
  }
  if (p.placement) {
    const PlacementChoice& c = *p.placement;
    os << "placement (" << c.rest.poses.size() << " stable resting poses, centre of mass of the "
       << (c.rest.solid ? "volume" : "surface") << "):\n  option  pose  as_given  probability  tip_deg  est_coverage  views  cell_time_s\n";
    for (std::size_t k = 0; k < c.options.size(); ++k) {
      const auto& o = c.options[k];
      std::snprintf(buf, sizeof buf, "  %s%5zu  %4s  %8s  %11.3f  %7.1f  %12.4f  %5zu  %11.1f\n",
                    static_cast<int>(k) == c.chosen ? "*" : " ", k + 1, o.pose < 0 ? "-" : std::to_string(o.pose + 1).c_str(),
                    o.as_given ? "yes" : "no", o.probability, o.tip_angle_rad * 180.0 / std::numbers::pi,
                    o.estimated_coverage, o.views, o.cell_time_s);
      os << buf;
    }
    os << "  chosen: " << c.reason << "\n";
  }
  return os.str();
}

}  // namespace scancell::planner
