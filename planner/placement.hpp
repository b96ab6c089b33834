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

}  // namespace scancell::planner
