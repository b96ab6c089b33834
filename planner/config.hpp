#pragma once
// YAML configuration of the sensor, the model specification and the planner settings. Every key carries its
// unit in its name; a missing, unknown, malformed or out-of-range key is refused with "file: key.path: why".
#include <cstdint>
#include <filesystem>
#include <string>

#include "common/key_declaration.hpp"
#include "planner/core/cover.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

/// placement: how the object rests on a turntable (planner/placement.hpp). Each limit is declared once here,
/// for the YAML loader and validate(PlacementSettings).
struct PlacementSettings {
  struct Limits {
    double lo, hi;
  };
  bool automatic = false;             // mode: auto (plan the stable resting poses, keep the best) | as_given
  int candidates = 4;                 // most probable stable poses planned
  double min_probability = 0.02;      // poses an object seldom settles in are not offered
  double min_tip_angle_rad = 0.1745;  // marginal poses (a tilt of less than this topples them) are not offered
  double coverage_tolerance = 0.005;  // estimated coverage within this (share of the area) is equal; fewer views win
  static constexpr Limits candidates_limits{1, 24}, min_probability_limits{0, 1}, min_tip_angle_limits{0, 1.5},
      coverage_tolerance_limits{0, 0.1};
};

struct PlannerSettings {
  ViewpointSettings viewpoints;
  CoverSettings cover;
  MatrixSettings matrix;
  PlacementSettings placement;
  /// matrix.countermeasures: auto — size them from the cell's pose-error model (tables 7.3-7.5); needs a cell.
  bool countermeasures_from_cell = false;
  /// matrix.free_space_countermeasures: a margin against the rough model's own error, for plans without a cell
  /// (merged, field by field the larger, with matrix.countermeasures): σz ≤ spec/(1 + b), ρ ≥ (1 + b)·spec and
  /// displaced rays. The view-minimal cover keeps the elements at the edge of the spec, and where the rough
  /// model errs many of them fail on the fine surface (docs/quality.md: m_v of the reachable area 0.982 on
  /// knot1 and couplingdown, 0.989 on rotor without any guard). Since session 41 it applies only where
  /// footprint_samples do not stand in for it: on a rough model that carries noise (σ_rm, thesis 5.4), whose
  /// triangles err at random too, or with footprint_samples 0 (choose_free_space_guard in plan.cpp). On a
  /// noise-free rough model the samples model its error where it is: free space 717 views with the margin,
  /// 537 with the samples, m_v of the reach ≥ 0.99 on 10 of 10 either way (the box with a blind hole 53 → 35
  /// views at 0.993). On a cell the plate and the axes limit m_v instead and the closed loop takes the rest:
  /// the same margin there cost 5-25 % more views for no m_v.
  Countermeasures free_space_countermeasures;
  /// matrix.footprint_samples: a plan that is not a replan, on a cell or in free space (there unless
  /// free_space_countermeasures applies, on a rough model with noise), predicts each row by
  /// up to this many samples of its footprint (the cells the closed loop measures it by,
  /// planner/core/footprint.hpp) instead of by its vertex; 0: by the vertex (thesis 3.3). A row whose
  /// footprint reaches past what a view sees (a rim by the plate, the side of a cleft, the far side of a bend
  /// its vertex normal averages away) is then known before a view is spent on it, which is what the oracle,
  /// aiming at fine vertices, knows (docs/quality.md: on the turntable cell knot1's single shot measures
  /// 0.9777 of the reach in 149 views by the vertex, 0.9880 in 175 by 8 samples; in free space, on a rough
  /// model without noise, where they replace free_space_countermeasures since session 41, knot1 0.9929 in
  /// 102 views against 0.9963 in 135 with the margin and 0.9850 in 92 with neither). 0 here, 4 in
  /// config/planner/default.yaml (cell: session 36).
  int footprint_samples = 0;
  /// matrix.footprint_sample_area_mm2: with footprint_samples, one sample per this much of a row's
  /// area, up to that many; a row under two samples' worth is predicted by its vertex (a crease row by
  /// crease_footprint_samples still). A vertex mispredicts a band about as wide as its row, so rows already
  /// that fine gain nothing from samples, and a mesh planned as given pays for them per row (docs/quality.md:
  /// 26k rows on the turntable 15.7 s with 4 each, 9.1 s at 4 mm²). 0 here: every row footprint_samples;
  /// 4 in config/planner/default.yaml (session 36).
  double footprint_sample_area_mm2 = 0.0;
  /// matrix.crease_footprint_samples / crease_angle_rad: a plan that is not a replan predicts the rows on a
  /// crease (crease_rows: a triangle more than crease_angle_rad from the row's normal) by up to this many
  /// footprint samples, each with its own triangle's normal (when footprint_samples is 0 or leaves the
  /// row to its vertex); 0: by the vertex. A crease row's bisector normal (a box's edge, a hole's rim, a
  /// pocket's floor by its wall) faces no surface that is there: views that measure both faces fail it, and
  /// the cover spent views on those rows alone (docs/quality.md: the box with a blind hole 39 views, 1.44×
  /// the cell oracle; by 4 samples 30). 0 here, 4 in config/planner/default.yaml. Under the registration
  /// constraint (eq. 4.2) two views overlap on such a row when each measures some of its samples
  /// (overlap_by_footprint_rows): counted by samples, a box's edge no longer let views of two faces register
  /// and the constraint left faces unplanned (docs/quality.md). Every cover counts overlap so, exact
  /// cover included (MeasurabilityMatrix::overlap).
  int crease_footprint_samples = 0;
  double crease_angle_rad = 0.6981317007977318;  // 40°: every 90° edge, however its faces weigh the normal
  std::uint64_t seed = 1;
  /// Keep every evaluated candidate in the plan (ViewPlan::candidate_views), for benchmarks and diagnostics.
  bool keep_candidates = false;
};

SensorModel load_sensor(const std::filesystem::path& file, KeyDeclarations* declared = nullptr);
ModelSpec load_spec(const std::filesystem::path& file);
/// `declared`, when given, receives what the loader declares for every key it reads (default and range:
/// common/yaml_section.hpp), for the test that holds docs/planner.md's key table to it.
PlannerSettings load_planner_settings(const std::filesystem::path& file, KeyDeclarations* declared = nullptr);

/// The same from YAML or JSON text (a plan file's `sensor` / `spec` objects); `where` prefixes messages.
SensorModel parse_sensor(const std::string& text, const std::string& where);
ModelSpec parse_spec(const std::string& text, const std::string& where);

/// The same checks load_* apply, for models built in code; throws ConfigError naming the key.
void validate(const SensorModel& sensor, const std::string& where = "sensor");
void validate(const ModelSpec& spec, const std::string& where = "spec");

const char* to_string(SensorKind k);
const char* to_string(ViewpointScheme s);
const char* to_string(CoverMode m);
const char* to_string(RegistrationNormalizer n);

}  // namespace scancell::planner
