#pragma once
// One planning pass of the 3M algorithm (thesis table 3.1): rough model -> candidate viewpoints ->
// measurability matrix -> set cover -> view plan, with per-stage wall times.
#include <atomic>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <optional>

#include "planner/kinematics/cell.hpp"
#include "planner/kinematics/resting_poses.hpp"
#include "planner/core/cell_viewpoints.hpp"
#include "planner/config.hpp"
#include "planner/core/cover.hpp"
#include "planner/core/exact_cover.hpp"
#include "planner/core/local_cover.hpp"
#include "planner/core/footprint.hpp"
#include "planner/core/measurability.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

/// Where the object came from, so any other tool can re-place the fine model: plan coordinates are input mesh
/// coordinates multiplied by `scale` (the recorded object transform is that uniform scale).
struct ObjectSource {
  std::string mesh_path;
  double scale = 1.0;
  MeshLoadReport load;
};

struct StageTimes {
  double load_s = 0.0, rough_model_s = 0.0, scene_s = 0.0, viewpoints_s = 0.0, matrix_s = 0.0, cover_s = 0.0;
  double matrix_samples_s = 0.0;  // the footprint samples' part of matrix_s (cover_by_samples)
  double total_s() const { return load_s + rough_model_s + scene_s + viewpoints_s + matrix_s + cover_s; }
};

/// Free space, the guard against the rough model's own error, chosen once per plan (choose_free_space_guard in
/// plan.cpp); on a cell always kNone (a single shot there is predicted by footprint samples whatever the rough
/// model).
enum class FreeSpaceGuard {
  kNone,             // a cell, or a mesh as given whose rows lie closer together than twice the visibility margin
  kMargin,           // matrix.free_space_countermeasures merged in (a rough model with noise, or footprint_samples 0)
  kFootprintSamples  // every row predicted by its footprint samples (a noise-free rough model)
};

struct ViewPlan {
  ObjectSource object;
  SensorModel sensor;
  ModelSpec spec;
  PlannerSettings settings;
  RoughModelOptions rough_options;
  RoughModelReport rough_report;
  RoughModel rough;
  GenerationReport generation;
  FreeSpaceGuard free_space_guard = FreeSpaceGuard::kNone;
  MatrixStats matrix_stats;
  std::size_t candidates = 0;
  std::size_t segments = 0;  // labelled surface patches of the rough model
  /// Rows predicted by footprint samples instead of their vertex (a replan's open rows, or a single shot's
  /// crease rows and, on a cell or under FreeSpaceGuard::kFootprintSamples, its rows of
  /// matrix.footprint_sample_area_mm2); 0: all by the vertex.
  std::size_t rows_by_footprint_samples = 0;
  double matrix_density = 0.0;
  std::size_t matrix_bytes = 0;
  std::vector<Viewpoint> views;  // in selection order
  std::vector<std::uint32_t> predicted_rows;  // rows the chosen views are predicted to measure (not yet measured)
  double predicted_gain_mm2 = 0.0;            // their area
  /// Per view (plan order), the rows of predicted_rows that view is predicted to measure: the closed loop's
  /// evidence per view, so that a row a view failed for a reason not of geometry (its sweep lost profiles)
  /// is not held against the row.
  std::vector<std::vector<std::uint32_t>> view_rows;
  std::vector<Viewpoint> candidate_views;  // every candidate the matrix evaluated (settings.keep_candidates)
  CoverResult cover;
  ExactReport exact;        // filled when settings.cover.mode == exact
  LocalSearchReport local_search;  // filled when the local search ran (settings.cover.local_search_iterations)
  std::optional<CellModel> cell;  // the cell planned for, with the object's placement on the table
  std::optional<PlacementChoice> placement;  // when the resting pose was chosen (planner/placement.hpp)
  CellGenerationReport cell_generation;  // cell-native candidates (cell_viewpoints.hpp), when the cell has them
  struct CellReport {
    std::size_t moved = 0, unreachable = 0, colliding = 0, duplicates = 0;
    double travel_s = 0.0, scan_s = 0.0;
  } cell_report;
  std::vector<JointVector> view_axes;  // per view, in plan order
  std::vector<double> view_move_s, view_scan_s;
  bool exact_used = false;
  StageTimes times;
  int threads = 0;
};

/// Plans views for an object already in millimetres. `threads` = 0 uses all cores; the plan does not depend
/// on it. With a cell: candidates are moved to the nearest reachable pose and checked for collisions, the
/// object is placed on the table, views are ordered for least travel and carry their axis targets.
/// Replanning (thesis table 3.1): `measured_rows` (one flag per rough-model row, from MeasuredCoverage on the
/// same mesh and options, hence the same rough model) removes what the executed views already measured from
/// the rows to cover; the estimate then refers to the remaining area only. `row_weight_scale` (one factor per
/// row, optional) down-weighs rows in the cover: rows the executed views were predicted to measure and did
/// not weigh less, so that no view is planned chiefly for them (their gain may fall under
/// cover.min_view_gain_mm2). `footprints` (optional, issue 15) replaces the vertex test of the rows it names
/// by the samples of what each still lacks (planner/core/footprint.hpp): a view is credited with such a row
/// only when it is predicted to fill enough of the row's unfilled footprint.
ViewPlan plan_views(TriangleMesh object_mm, const SensorModel& sensor, const ModelSpec& spec,
                    const PlannerSettings& settings, const RoughModelOptions& rough_options, int threads = 0,
                    const CellModel* cell = nullptr, const std::vector<std::uint8_t>* measured_rows = nullptr,
                    const std::vector<double>* row_weight_scale = nullptr, const std::atomic<int>* cancel = nullptr,
                    const RowFootprints* footprints = nullptr);

/// The documented plan file (docs/plan-format.md).
nlohmann::json plan_to_json(const ViewPlan& plan);

/// The placement choice as plan files and job results record it (docs/plan-format.md, summary.placement).
nlohmann::json placement_to_json(const PlacementChoice& choice);

/// A short table for people: views, estimated measurability, timings.
std::string plan_summary(const ViewPlan& plan);

}  // namespace scancell::planner
