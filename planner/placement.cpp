#include "planner/placement.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/errors.hpp"

namespace scancell::planner {

namespace {

void check_range(const char* key, double v, double lo, double hi) {
  if (!(v >= lo && v <= hi)) {
    std::ostringstream s;
    s << "placement." << key << ": " << v << " is outside [" << lo << ", " << hi << "]";
    throw ConfigError(s.str());
  }
}

/// A pose the choice may take: stable, settled in often enough, not toppled by a small tilt.
bool offered(const RestingPose& r, const PlacementSettings& s) {
  return r.probability >= s.min_probability && r.tip_angle_rad >= s.min_tip_angle_rad;
}

/// More area first; within the tolerance, fewer views; then the likelier pose.
bool better(const PlacementOption& a, const PlacementOption& b, double tolerance) {
  if (a.estimated_coverage > b.estimated_coverage + tolerance) return true;
  if (b.estimated_coverage > a.estimated_coverage + tolerance) return false;
  if (a.views != b.views) return a.views < b.views;
  return a.probability > b.probability;
}

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << v;
  return s.str();
}

}  // namespace

void validate(const PlacementSettings& s) {
  using L = PlacementSettings;
  check_range("candidates", s.candidates, L::candidates_limits.lo, L::candidates_limits.hi);
  check_range("min_probability", s.min_probability, L::min_probability_limits.lo, L::min_probability_limits.hi);
  check_range("min_tip_angle_rad", s.min_tip_angle_rad, L::min_tip_angle_limits.lo, L::min_tip_angle_limits.hi);
  check_range("coverage_tolerance", s.coverage_tolerance, L::coverage_tolerance_limits.lo, L::coverage_tolerance_limits.hi);
}

ViewPlan plan_with_placement(const TriangleMesh& object_mm, const SensorModel& sensor, const ModelSpec& spec,
                             const PlannerSettings& settings, const RoughModelOptions& rough_options, int threads,
                             const CellModel& cell, const std::atomic<int>* cancel) {
  const PlacementSettings& placement = settings.placement;
  validate(placement);
  PlacementChoice choice;
  choice.rest = resting_poses(object_mm);
  const Eigen::Matrix3d given = cell.object_on_table.linear();
  const Eigen::Vector3d given_down = given.transpose() * -Eigen::Vector3d::UnitZ();  // object frame
  bool given_offered = false;
  for (int k = 0; k < static_cast<int>(choice.rest.poses.size()); ++k) {
    const RestingPose& r = choice.rest.poses[k];
    if (static_cast<int>(choice.options.size()) >= placement.candidates) break;
    if (!offered(r, placement)) continue;
    PlacementOption o;
    o.pose = k;
    // As given when it rests on the same face (within 2°): keep the configured rotation about the table axis.
    o.as_given = r.down_object.dot(given_down) > std::cos(2.0 * M_PI / 180.0);
    given_offered = given_offered || o.as_given;
    o.object_to_table = o.as_given ? given : r.object_to_table;
    o.probability = r.probability;
    o.tip_angle_rad = r.tip_angle_rad;
    choice.options.push_back(o);
  }
  if (!given_offered) {
    PlacementOption o;
    o.as_given = true;
    o.object_to_table = given;
    const int k = settling_pose(choice.rest, given_down);
    if (k >= 0 && choice.rest.poses[k].down_object.dot(given_down) > std::cos(2.0 * M_PI / 180.0)) {
      o.pose = k;  // a stable pose, just not an offered one (marginal or seldom)
      o.probability = choice.rest.poses[k].probability;
      o.tip_angle_rad = choice.rest.poses[k].tip_angle_rad;
    } else if (k >= 0) {
      o.settles_on = k;
      o.settle_angle_rad = std::acos(std::clamp(choice.rest.poses[k].down_object.dot(given_down), -1.0, 1.0));
    }
    choice.options.push_back(o);
  }
  std::vector<ViewPlan> plans;
  for (auto& o : choice.options) {
    CellModel c = cell;
    c.object_on_table.linear() = o.object_to_table;
    plans.push_back(plan_views(object_mm, sensor, spec, settings, rough_options, threads, &c, nullptr, nullptr, cancel));
    const ViewPlan& p = plans.back();
    o.estimated_coverage = p.cover.cumulative_fraction.empty() ? 0.0 : p.cover.cumulative_fraction.back();
    o.views = p.views.size();
    o.cell_time_s = p.cell_report.travel_s + p.cell_report.scan_s;
    o.plan_s = p.times.total_s();
  }
  // Offered: a stable, not marginal pose an object settles in often enough (an as-given orientation that is
  // none of those is shown for comparison only: on a real plate it would not stay).
  for (int k = 0; k < static_cast<int>(choice.options.size()); ++k)
    if (choice.options[k].pose >= 0 && offered(choice.rest.poses[choice.options[k].pose], placement) && (choice.chosen < 0 || better(choice.options[k], choice.options[choice.chosen], placement.coverage_tolerance)))
      choice.chosen = k;
  if (choice.chosen < 0)
    throw DataError("placement: none of the object's " + std::to_string(choice.rest.poses.size()) +
                    " resting poses is stable enough to offer (placement.min_tip_angle_rad " +
                    fixed(placement.min_tip_angle_rad, 3) + ", placement.min_probability " + fixed(placement.min_probability, 3) +
                    "); place it as given instead");
  const PlacementOption& best = choice.options[choice.chosen];
  std::ostringstream why;
  why << (best.as_given ? "as given" : "resting pose " + std::to_string(best.pose + 1)) << ": estimated coverage "
      << fixed(best.estimated_coverage, 3) << " with " << best.views << " views";
  for (const auto& o : choice.options)
    if (&o != &best && o.as_given)
      why << " (as given: " << fixed(o.estimated_coverage, 3) << " with " << o.views << " views"
          << (o.pose >= 0 ? "" : o.settles_on < 0 ? ", not a stable pose"
                                                  : ", not a stable pose: let go, it settles in pose " + std::to_string(o.settles_on + 1) + ", " +
                                                        fixed(o.settle_angle_rad * 180.0 / M_PI, 0) + "° away")
          << ")";
  choice.reason = why.str();
  ViewPlan p = std::move(plans[choice.chosen]);
  p.placement = std::move(choice);
  return p;
}

NextSetup plan_next_setup(const TriangleMesh& object_mm, const SensorModel& sensor, const ModelSpec& spec,
                          const PlannerSettings& settings, const RoughModelOptions& rough_options, int threads,
                          const CellModel& cell, const Eigen::Matrix3d& current,
                          const std::vector<std::uint8_t>& measured, const std::atomic<int>* cancel) {
  const PlacementSettings& placement = settings.placement;
  validate(placement);
  NextSetup next;
  next.rest = resting_poses(object_mm);
  const Eigen::Vector3d current_down = current.transpose() * -Eigen::Vector3d::UnitZ();
  // What is left decides the gain, not the pose: the same rough model (same mesh and options) in every pose.
  PlannerSettings s = settings;
  s.cover.min_view_gain = 0.0;  // a second setup goes after every open row, as the closed loop does
  int best = -1;                // into next.options
  for (int k = 0; k < static_cast<int>(next.rest.poses.size()); ++k) {
    const RestingPose& r = next.rest.poses[k];
    if (static_cast<int>(next.options.size()) >= placement.candidates) break;
    if (!offered(r, placement)) continue;
    if (r.down_object.dot(current_down) > std::cos(2.0 * M_PI / 180.0)) continue;  // the setup just measured
    CellModel c = cell;
    c.object_on_table.linear() = r.object_to_table;
    const ViewPlan p = plan_views(object_mm, sensor, spec, s, rough_options, threads, &c, &measured, nullptr, cancel);
    if (next.unmeasured_area_mm2 == 0.0)
      for (std::size_t row = 0; row < p.rough.size(); ++row)
        if (!measured.at(row)) next.unmeasured_area_mm2 += p.rough.area_mm2[row];
    PlacementOption o;
    o.pose = k;
    o.object_to_table = r.object_to_table;
    o.probability = r.probability;
    o.tip_angle_rad = r.tip_angle_rad;
    o.estimated_coverage = next.unmeasured_area_mm2 > 0.0 ? p.predicted_gain_mm2 / next.unmeasured_area_mm2 : 0.0;
    o.views = p.views.size();
    o.cell_time_s = p.cell_report.travel_s + p.cell_report.scan_s;
    o.plan_s = p.times.total_s();
    next.options.push_back(o);
    if (o.estimated_coverage > 0.0 && (best < 0 || better(o, next.options[best], placement.coverage_tolerance))) {
      best = static_cast<int>(next.options.size()) - 1;
      next.pose = k;
      next.object_to_table = r.object_to_table;
      next.predicted_gain_mm2 = p.predicted_gain_mm2;
      next.views = p.views.size();
      next.predicted_rows = p.predicted_rows;
    }
  }
  std::ostringstream why;
  if (next.pose < 0) {
    why << "no other stable resting pose lets the cell measure any of the " << fixed(next.unmeasured_area_mm2, 0)
        << " mm2 left (" << next.options.size() << " planned)";
  } else {
    why << "resting pose " << next.pose + 1 << ": " << next.views << " views predicted to measure "
        << fixed(next.predicted_gain_mm2, 0) << " of the " << fixed(next.unmeasured_area_mm2, 0) << " mm2 left";
  }
  next.reason = why.str();
  return next;
}

}  // namespace scancell::planner
