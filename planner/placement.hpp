#pragma once
// Which way up the object goes on the turntable (issue 15 item 5). On a turntable cell the support face and
// what the plate shadows are never measured, so the resting pose decides how much of the object one setup
// can measure and with how many views. The choice plans the most probable stable poses of the object and
// keeps the one that measures the most area with the fewest views.
#include <atomic>

#include "planner/kinematics/resting_poses.hpp"
#include "planner/plan.hpp"

namespace scancell::planner {

/// Validates PlacementSettings' declared limits (planner/config.hpp); ConfigError naming the key (placement.<key>).
void validate(const PlacementSettings& s);

/// Plans `object_mm` on `cell` in each offered resting pose (settings.placement; and as given, when that is not
/// one of them) and returns the plan of the chosen one, with every option's figures and the reason in
/// `ViewPlan::placement` and the chosen rotation in the plan's cell (object_on_table). Deterministic: the same
/// inputs give the same choice for any thread count.
ViewPlan plan_with_placement(const TriangleMesh& object_mm, const SensorModel& sensor, const ModelSpec& spec,
                             const PlannerSettings& settings, const RoughModelOptions& rough_options, int threads,
                             const CellModel& cell, const std::atomic<int>* cancel = nullptr);

/// The second setup (issue 20): after a turntable job measured what it could in one resting pose, the
/// stable pose that lets the cell measure most of what is still unmeasured.
struct NextSetup {
  int pose = -1;                      // index into rest.poses; -1: no offered pose gains anything
  Eigen::Matrix3d object_to_table = Eigen::Matrix3d::Identity();
  double predicted_gain_mm2 = 0.0;    // unmeasured rough-model area its plan is predicted to measure
  std::size_t views = 0;              // views of that plan
  double unmeasured_area_mm2 = 0.0;   // what is left now (rows not in `measured`)
  std::vector<std::uint32_t> predicted_rows;
  std::vector<PlacementOption> options;  // every pose planned (estimated_coverage: the gain over the unmeasured area)
  RestingPoses rest;
  std::string reason;
};

/// Plans `object_mm` in every offered stable resting pose other than the current one (`current` object to
/// table; within 2°), covering only rows `measured` leaves open (one flag per rough-model row, as plan_views
/// takes them), and picks the largest predicted gain, fewer views within placement.coverage_tolerance of the
/// unmeasured area. Offered: placement.min_probability / min_tip_angle_rad, at most candidates of them.
NextSetup plan_next_setup(const TriangleMesh& object_mm, const SensorModel& sensor, const ModelSpec& spec,
                          const PlannerSettings& settings, const RoughModelOptions& rough_options, int threads,
                          const CellModel& cell, const Eigen::Matrix3d& current,
                          const std::vector<std::uint8_t>& measured, const std::atomic<int>* cancel = nullptr);

}  // namespace scancell::planner
