#pragma once
// What the job runner's files share, and only they: the running job's state (JobRunner::Job) and a few
// helpers. Not an interface: nothing outside the runner includes it (issue 17: a runner split by job).
//   job_runner.cpp      the 3M loop: read the request, plan round 0, execute a round, replan or close
//   job_view.cpp        one view: move, sweep, register to the model, store, count its coverage
//   job_rough_scan.cpp  a bounding-box job's rough scan: exploration views, fusion, the rough model
//   job_setups.cpp      further setups (issue 20): the advice, the operator's turn, alignment, the setup's plan
//   job_finish.cpp      the job's end: result, product (cloud, model), inspection report, ground-truth checks
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/errors.hpp"
#include "daemon/job_runner.hpp"

namespace scancell::daemon {

struct JobRunner::Job {
  std::int64_t id = 0;
  const std::atomic<int>* stop = nullptr;  // the run's stop request (pause, abort, shutdown)
  JobRequest request;
  planner::ModelSpec spec;
  planner::PlannerSettings settings;
  planner::RoughModelOptions rough_options;
  planner::TriangleMesh object;          // rough model input, mm, object frame
  std::optional<planner::RoughModel> rough;
  std::unique_ptr<planner::MeasuredCoverage> coverage;
  std::unique_ptr<planner::ModelCloud> cloud;  // what views register to: the rough model, then the registered views
  std::unique_ptr<ScanHead> head;
  planner::CellModel cell;               // with the object's placement on the table
  planner::TriangleMesh truth_table;     // simulation, bounding-box jobs: the object as it stands on the table
  nlohmann::json rough_quality;               // simulation, bounding-box jobs: the fused rough model against the truth
  nlohmann::json placement;                   // the resting-pose choice of round 0, when placement was auto
  planner::TriangleMesh truth_object;    // simulation: the object on the table, in the plan's object frame
  std::vector<std::uint32_t> unmeasurable;  // rows no candidate of the first plan measures
  Progress progress;
  int round = 0;
  double estimated_total = 0.0;
  double view_seconds = 0.0;        // mean executed view time this session
  int views_timed = 0;
  std::vector<double> planned_view_s;
  /// Per plan and view (0-based), the predicted rows its sweep passed without a profile (held_rows).
  std::map<std::int64_t, std::map<int, std::vector<std::uint32_t>>> excused;
  std::vector<std::vector<std::uint32_t>> view_rows;  // the executing round's rows per view
  // Setups (issue 20): the one being measured (1-based), its first plan round, how many the job may use,
  // and, from the second on, the placement asked of the operator (object to table).
  int setup = 1;
  int setup_first_round = 0;
  int max_setups = 1;
  Eigen::Isometry3d asked = Eigen::Isometry3d::Identity();
};

namespace job_detail {

namespace sp = scancell::planner;
using nlohmann::json;

std::string fmt(double v, int digits = 4);

/// The journal's record of each view of a plan: pose, scan length, axis targets, planned move and scan times.
std::vector<std::string> view_records(const sp::ViewPlan& p);

Eigen::Isometry3d pose_from(const json& a, const std::string& what);

/// The cell with the part resting exactly at `pose` (object to table), in the form plan_views places it: the
/// pose's rotation and the plate offset that reproduces it (a setup aligned off centre and turned).
sp::CellModel resting_at(const sp::CellModel& cell, const sp::TriangleMesh& object, const Eigen::Isometry3d& pose);

/// Whether every image carries the in-process virtual scanner's truth (not a device on the wire).
bool all_have_truth(const std::vector<sp::RangeImage>& images);

/// Planning that a pause, abort or shutdown stops at its next stage boundary (or inside the matrix build):
/// the request becomes an Interrupted like one between moves; nothing of the plan is journalled.
template <class Plan>
sp::ViewPlan plan_or_stop(Plan&& plan, const std::atomic<int>& stop) {
  try {
    return plan();
  } catch (const scancell::PlanCancelled& e) {
    throw Interrupted(static_cast<StopRequest>(stop.load()), std::string("during planning (") + e.what() + ")");
  }
}

}  // namespace job_detail
}  // namespace scancell::daemon
