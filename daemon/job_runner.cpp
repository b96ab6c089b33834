#include "daemon/job_runner.hpp"
#include "daemon/job_runner_detail.hpp"
#include "common/json_matrix.hpp"
#include "common/timing.hpp"

#include "daemon/acquire.hpp"
#include "daemon/job_product.hpp"
#include "daemon/job_result.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <sstream>
#include <thread>

#include "common/errors.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/placement.hpp"
#include "planner/kinematics/pose_error.hpp"
#include "planner/geometry/surface_distance.hpp"
#include "planner/sim/verify.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::daemon {
using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace job_detail;

namespace job_detail {

std::string fmt(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

/// The journal's record of each view of a plan: pose, scan length, axis targets, planned move and scan times.
std::vector<std::string> view_records(const sp::ViewPlan& p) {
  std::vector<std::string> out;
  for (std::size_t k = 0; k < p.views.size(); ++k)
    out.push_back(json({{"camera_to_object", row_major_json(p.views[k].transform())},
                        {"scan_length_mm", p.views[k].scan_length_mm},
                        {"axes", p.view_axes.at(k)},
                        {"move_s", p.view_move_s.at(k)},
                        {"scan_s", p.view_scan_s.at(k)}})
                      .dump());
  return out;
}

Eigen::Isometry3d pose_from(const json& a, const std::string& what) {
  return Eigen::Isometry3d(scancell::matrix4_from_row_major(a, what));
}

/// The cell with the part resting exactly at `pose` (object to table), in the form plan_views places it: the
/// pose's rotation and the plate offset that reproduces it (a setup aligned off centre and turned).
sp::CellModel resting_at(const sp::CellModel& cell, const sp::TriangleMesh& object, const Eigen::Isometry3d& pose) {
  sp::CellModel c = cell;
  c.object_on_table.linear() = pose.linear();
  c.object_on_table.translation() = sp::plate_offset_of(object, pose);
  return c;
}

/// Whether every image carries the in-process virtual scanner's truth (not a device on the wire).
bool all_have_truth(const std::vector<sp::RangeImage>& images) {
  return std::all_of(images.begin(), images.end(), [](const sp::RangeImage& im) { return im.has_truth(); });
}

}  // namespace job_detail

/// Every executed round's plan info, with the rows its views' sweeps passed without a profile (held_rows).
std::vector<json> JobRunner::round_infos(const Job& j) {
  std::vector<json> infos;
  for (const auto& [plan, round] : journal_.plan_rounds(j.id)) {
    if (round < 0) continue;
    json info = json::parse(journal_.plan_info(plan));
    // The closed loop's evidence is per setup: a row that failed with the part in one pose may be measured
    // easily in the next.
    if (info.value("setup", 1) != j.setup) continue;
    json ex = json::object();
    if (const auto e = j.excused.find(plan); e != j.excused.end())
      for (const auto& [view, rows] : e->second) ex[std::to_string(view)] = rows;
    info["excused_rows"] = ex;
    infos.push_back(std::move(info));
  }
  return infos;
}

JobRunner::JobRunner(Journal& journal, const CellModels& models, dr::Positioner& positioner, ScanHeadFactory heads,
                     JobSettings settings, Report report)
    : journal_(journal), models_(models), positioner_(positioner), heads_(std::move(heads)),
      settings_(std::move(settings)), report_(std::move(report)), trace_(settings_.phase_trace_file) {
  bool sweep = false;
  for (const auto& a : models_.cell.axes) sweep = sweep || a.name == "sweep";
  if (!sweep)
    throw scancell::ConfigError("cell '" + models_.cell.name + "': no 'sweep' axis; the line-scan execution needs one");
}

void JobRunner::transition(Job& j, JobState s, const std::string& cause) {
  journal_.set_state(j.id, s, cause);
  trace_.mark(to_string(s));
  j.progress.state = s;
  j.progress.event = std::string(to_string(s)) + (cause.empty() ? "" : ": " + cause);
  report_(j.progress);
}

/// The job's request, spec, settings and object, read from the journal; a bad one faults the job (false).
bool JobRunner::read_request(Job& j, const JobRecord& rec) {
  try {
    j.request = JobRequest::from_json(json::parse(rec.request_json));
    j.spec = j.request.spec.empty() ? models_.spec : sp::load_spec(j.request.spec);
    j.settings = j.request.settings.empty() ? models_.settings : sp::load_planner_settings(j.request.settings);
    if (j.request.rough_vertices) j.rough_options.target_vertices = *j.request.rough_vertices;
    j.max_setups = j.request.setups.value_or(settings_.max_setups);
    if (!j.request.placement.empty()) j.settings.placement.automatic = j.request.placement == "auto";
    if (j.request.bbox_mm) j.settings.placement.automatic = false;  // it already stands on the table
    j.rough_options.seed = j.settings.seed;
    // Every round and setup of a job is covered without the between-view registration constraint (thesis
    // 4.4.3): each view registers to the object's model (ModelCloud in restore()), not to the views before
    // it, so the constraint buys nothing here; and with it a coarse, boxy rough model can leave a face
    // without a view once crease rows are judged by their faces.
    j.settings.cover = sp::registered_to_model(j.settings.cover);
    if (!j.request.bbox_mm) j.object = load_object(j.request.mesh, j.request.fit_mm);
    else if (j.request.truth.empty()) throw scancell::DataError("a bounding-box job needs 'truth' in simulation: what stands on the table");
  } catch (const std::exception& e) {
    j.progress.fault_kind = "job";
    transition(j, JobState::faulted, std::string("job input: ") + e.what());
    return false;
  }
  return true;
}

/// Round 0: the first plan (with the resting-pose choice when placement is auto), journalled; a plan
/// without views ends the job (stalled), which is returned.
std::optional<JobState> JobRunner::plan_first_round(Job& j, const std::atomic<int>& stop) {
  transition(j, JobState::planning);
  sp::ViewPlan p = plan_or_stop([&] {
    if (j.settings.placement.automatic)
      return sp::plan_with_placement(j.object, models_.sensor, j.spec, j.settings, j.rough_options,
                                     settings_.planner_threads, models_.cell, &stop);
    return sp::plan_views(j.object, models_.sensor, j.spec, j.settings, j.rough_options, settings_.planner_threads,
                          &models_.cell, nullptr, nullptr, &stop);
  }, stop);
  j.rough = p.rough;
  j.unmeasurable = p.cover.unmeasurable_rows;
  const std::vector<std::string> poses = view_records(p);
  json info = round_info(j, p, 0, 1, std::vector<std::uint8_t>(p.rough.size(), 0));
  info["unmeasurable_rows"] = j.unmeasurable;
  if (p.placement) {
    info["placement"] = sp::placement_to_json(*p.placement);
    journal_.event(j.id, "placement: " + p.placement->reason);
  }
  if (p.views.empty()) {
    j.cell = *p.cell;
    j.coverage = std::make_unique<sp::MeasuredCoverage>(*j.rough, j.spec, settings_.coverage);
    finish(j, JobState::stalled, "the planner found no view that measures any of the rough model");
    return JobState::stalled;
  }
  journal_.add_plan(j.id, 0, poses, info.dump());
  return std::nullopt;
}

/// The job's state from the journal, as after a restart: placement and unmeasurable rows of round 0, the
/// rough model, the measured coverage and the registration cloud from every stored scan, and the head (with
/// what stands on the table, in simulation).
void JobRunner::restore(Job& j, const std::vector<std::int64_t>& plans) {
  // The current setup's first round carries its placement and the rows nothing can measure in it (the first
  // round's, the resting-pose choice too).
  std::size_t first = 0;
  j.setup = 1;
  for (std::size_t k = 0; k < plans.size(); ++k) {
    const int setup = json::parse(journal_.plan_info(plans[k])).value("setup", 1);
    if (setup > j.setup) {
      j.setup = setup;
      first = k;
    }
  }
  j.setup_first_round = static_cast<int>(first);
  const json info0 = json::parse(journal_.plan_info(plans[first]));
  j.cell = models_.cell;
  j.cell.object_on_table = pose_from(info0.at("object_on_table"), "plan info object_on_table");
  j.unmeasurable = info0.at("unmeasurable_rows").get<std::vector<std::uint32_t>>();
  if (j.setup > 1) j.asked = pose_from(info0.at("asked_object_to_table"), "plan info asked_object_to_table");
  if (const json round0 = json::parse(journal_.plan_info(plans.front())); round0.contains("placement")) j.placement = round0.at("placement");
  if (!j.rough) j.rough = sp::build_rough_model(j.object, j.rough_options);
  if (j.rough->size() != info0.at("rows").get<std::size_t>())
    throw scancell::DataError("job " + std::to_string(j.id) + ": the rough model now has " + std::to_string(j.rough->size()) +
                        " rows, the journalled plan " + std::to_string(info0.at("rows").get<std::size_t>()) +
                        " (mesh file or planner changed since the job was planned)");
  j.coverage = std::make_unique<sp::MeasuredCoverage>(*j.rough, j.spec, settings_.coverage);
  // Views register to the object's mesh as given, not to the planner's decimated rows: every coarsening is
  // a bias of registration along the views' rays (what is left of it the PN patches take out). A fused
  // rough model is the exception: at full resolution it is a voxel staircase whose face normals scatter by
  // tens of degrees, so its decimation (the rows' mesh, flat where the object is) is the better target.
  if (settings_.register_views)
    j.cloud = std::make_unique<sp::ModelCloud>(sp::ModelCloud::from_mesh(j.request.bbox_mm ? j.rough->mesh() : j.object, 1.0));
  std::vector<Eigen::Vector3d> cloud_points, cloud_normals;
  for (auto plan : plans) {
    const auto rows_of_view = json::parse(journal_.plan_info(plan)).value("view_rows", std::vector<std::vector<std::uint32_t>>{});
    for (const auto& s : journal_.scans(plan)) {
      if (!s.note.empty()) continue;  // stored, but not counted (its registration failed)
      const sp::RangeImage img = sp::range_image_from_ply(journal_.read_scan(s), s.file);
      if (s.view >= 0 && static_cast<std::size_t>(s.view) < rows_of_view.size())
        note_lost_profiles(j, plan, s.view, img, rows_of_view[static_cast<std::size_t>(s.view)]);
      j.coverage->add(img);
      if (j.cloud) sp::image_points_normals(img, 3, cloud_points, cloud_normals);
    }
  }
  if (j.cloud && !cloud_points.empty()) j.cloud->add(cloud_points, cloud_normals);
  j.progress.measured = j.coverage->coverage();

  // What is on the table, for a simulated head: the object (ground truth) in the plan's object frame, and
  // the plate.
  if (j.request.bbox_mm) {
    j.truth_object = j.truth_table;
    const Eigen::Isometry3d table_to_object = j.cell.object_on_table.inverse();
    for (auto& v : j.truth_object.vertices) v = table_to_object * v;
  } else {
    j.truth_object = load_object(j.request.truth.empty() ? j.request.mesh : j.request.truth, j.request.fit_mm);
  }
  // From the second setup on, the part lies as the simulated operator put it down, which the cell knows only
  // as well as the alignment found it: the truth in the plan's object frame is off by what the alignment missed.
  sp::TriangleMesh on_table = j.truth_object;
  if (j.setup > 1) {
    const Eigen::Isometry3d to_plan = j.cell.object_on_table.inverse() * actual_placement(j, j.setup, j.asked);
    for (auto& v : on_table.vertices) v = to_plan * v;
  }
  j.head = heads_(sp::with_fixtures(on_table, j.cell), on_table.triangles.size(), j.cell);
}

/// Round `plans.back()`: its views executed from the first unfinished one, then the cloud so far written.
/// Returns the round's plan info.
json JobRunner::execute_round(Job& j, const std::vector<std::int64_t>& plans, const std::atomic<int>& stop) {
  const std::int64_t plan = plans.back();
  j.round = static_cast<int>(plans.size()) - 1;
  j.progress.round = j.round;
  const json info = json::parse(journal_.plan_info(plan));
  const auto views = journal_.views(plan);
  j.view_rows = info.value("view_rows", std::vector<std::vector<std::uint32_t>>{});
  j.progress.views = static_cast<int>(views.size());
  j.progress.view = 0;
  // The estimate for the whole model: measured before this round plus the round's share of the rest.
  double measured_before = j.progress.measured;
  j.estimated_total = j.round == 0 ? info.at("estimated").get<double>()
                                   : info.value("estimated_total", measured_before);
  j.progress.estimated = j.estimated_total;
  j.planned_view_s.clear();
  for (const auto& v : views) {
    const json pj = json::parse(v.pose_json);
    j.planned_view_s.push_back(pj.value("move_s", 0.0) + pj.value("scan_s", 0.0));
  }
  if (journal_.first_unfinished_view(plan)) {
    const int done_views = static_cast<int>(std::count_if(views.begin(), views.end(), [](const ViewRecord& v) { return v.stored; }));
    transition(j, JobState::executing,
               "round " + std::to_string(j.round) + ", " + std::to_string(views.size()) + " views" +
                   (done_views ? ", resuming at view " + std::to_string(done_views + 1) : ""));
    for (const auto& v : views) {
      if (v.stored) continue;
      const auto why = static_cast<StopRequest>(stop.load());
      if (why != StopRequest::none) throw Interrupted(why, "before view " + std::to_string(v.index + 1));
      execute_view(j, plan, v, stop);
    }
  }
  transition(j, JobState::verifying);
  {
    // Kept current after each round: the registered cloud so far (durable, like the scans).
    const CloudSummary c =
        write_job_cloud(load_job_views(journal_, j.id), j.id, j.spec, settings_.jobs_dir / std::to_string(j.id) / "cloud.ply", false,
                        settings_.cloud_spacing_mm);
    journal_.event(j.id, "round " + std::to_string(j.round) + ": cloud.ply holds " + std::to_string(c.points) +
                           " spec-compliant samples from " + std::to_string(c.views) + " views");
  }
  return info;
}

/// A further round's plan info: what it plans (views, rows, predicted gain) for the rows `measured` leaves
/// open, its estimate for the whole model, and where the part rests; what a resume and the result read.
json JobRunner::round_info(const Job& j, const sp::ViewPlan& p, int round, int setup, const std::vector<std::uint8_t>& measured) const {
  const double est_rest = p.cover.cumulative_fraction.empty() ? 0.0 : p.cover.cumulative_fraction.back();
  double rest_area = 0.0;
  for (std::size_t r = 0; r < measured.size(); ++r) rest_area += measured[r] ? 0.0 : j.rough->area_mm2[r];
  return {{"round", round},
          {"setup", setup},
          {"object_on_table", row_major_json(p.cell->object_on_table.matrix())},
          {"rows", j.rough->size()},
          {"estimated", est_rest},
          {"estimated_total", j.progress.measured + est_rest * rest_area / j.rough->total_area_mm2},
          {"measured_before", j.progress.measured},
          {"candidates", p.candidates},
          {"views", p.views.size()},
          {"predicted_rows", p.predicted_rows},
          {"view_rows", p.view_rows},
          {"predicted_gain_mm2", p.predicted_gain_mm2},
          {"plan_s", p.times.total_s()}};
}

/// A round's account in the journal: its predicted and realized gain, and the rows excused by lost profiles.
void JobRunner::journal_round(Job& j, std::int64_t plan, const json& info, const std::vector<json>& infos) {
  const json g = round_gains(infos, j.progress.measured, j.rough->total_area_mm2).back();
  journal_.event(j.id, "round " + std::to_string(j.round) + ": " + std::to_string(info.value("views", 0)) + " views, predicted gain " +
                         fmt(g.at("predicted_gain_mm2").get<double>(), 1) + " mm2, realized " +
                         fmt(g.at("realized_gain_mm2").get<double>(), 1) + " mm2" +
                         (g.at("under_20_percent").get<bool>() ? " (under 20 % of the prediction)" : ""));
  std::vector<std::uint32_t> passed;
  for (const auto& [view, rows] : j.excused[plan]) passed.insert(passed.end(), rows.begin(), rows.end());
  std::sort(passed.begin(), passed.end());
  passed.erase(std::unique(passed.begin(), passed.end()), passed.end());
  if (!passed.empty())
    journal_.event(j.id, "round " + std::to_string(j.round) + ": " + std::to_string(passed.size()) + " predicted rows lay where " +
                           std::to_string(j.excused[plan].size()) + (j.excused[plan].size() == 1 ? " view's sweep" : " views' sweeps") +
                           " lost profiles; not counted as failures");
}

/// After a round: its predicted and realized gain and the rows it failed, then the end (done, or stalled:
/// every open row given up, max_rounds, nothing new measured, a replan with no view or too little gain per
/// view) or the next round's plan, journalled. Returns the end state, or nothing to run the next round.
std::optional<JobState> JobRunner::close_or_replan(Job& j, std::int64_t plan, const json& info, const std::atomic<int>& stop) {
  const std::vector<json> infos = round_infos(j);
  journal_round(j, plan, info, infos);
  // Rows the executed rounds were predicted to measure and did not: retired after
  // jobs.retire_after_failures such rounds (needs attention), down-weighted before.
  std::vector<std::uint8_t> measured_now = j.coverage->measured_rows();
  for (auto r : j.unmeasurable) measured_now[r] = 1;
  const std::vector<std::uint8_t> fails = failure_counts(infos, measured_now);
  const std::vector<std::uint8_t> retired =
      given_up_rows(infos, measured_now, j.progress.measured, settings_.retire_after_failures, j.rough->total_area_mm2);
  std::size_t n_retired = 0;
  double retired_area = 0.0;
  for (std::size_t r = 0; r < fails.size(); ++r)
    if (retired[r]) {
      ++n_retired;
      retired_area += j.rough->area_mm2[r];
    }
  // A hypothetical row (the rough scan never saw that surface) that views aimed at and did not measure
  // is most likely not surface at all: the real one lies deeper, and the views measured it instead.
  const RowTally t = tally_unmeasured(*j.rough, j.coverage->unmeasured_rows(), j.unmeasurable);
  const std::size_t open = t.open, guessed = t.guessed;
  const double open_area = t.open_area, impossible_area = t.impossible_area, guessed_area = t.guessed_area;
  const std::string summary = "measured " + fmt(j.progress.measured) + " of the rough model; " + std::to_string(open) +
                              " measurable rows left (" + fmt(open_area, 1) + " mm2), " +
                              fmt(impossible_area, 1) + " mm2 no view in this cell can measure" +
                              (guessed ? ", " + std::to_string(guessed) + " hypothetical rows unconfirmed (" + fmt(guessed_area, 1) + " mm2)" : "");
  journal_.event(j.id, summary);
  // Hypothetical rows are chased for one replanning round (views aimed there explore what the rough scan
  // missed); after that, only measurable rows of seen surface keep the job open.
  if (open == 0 && (guessed == 0 || j.round >= 1)) {
    return end_setup(j, JobState::done, "spec met: " + summary);
  }
  // How the stalls below name the rows that need attention.
  const std::string attention = std::to_string(n_retired) + " rows (" + fmt(retired_area, 1) + " mm2) need attention: ";
  std::size_t open_retired = 0;
  for (auto r : j.coverage->unmeasured_rows())
    open_retired += retired[r] && (j.rough->hypothetical.empty() || !j.rough->hypothetical[r]);
  if (open_retired == open && (guessed == 0 || j.round >= 1)) {
    return end_setup(j, JobState::stalled, attention + "predicted measurable by " +
                                     std::to_string(settings_.retire_after_failures) +
                                     " rounds, or by a replanning round that realized under 20 % of its prediction, and not measured; " + summary);
  }
  if (j.round - j.setup_first_round + 1 >= settings_.max_rounds) {
    return end_setup(j, JobState::stalled, "after " + std::to_string(j.round - j.setup_first_round + 1) + " rounds" +
                                              (j.setup > 1 ? " of setup " + std::to_string(j.setup) : "") + ": " + attention + summary);
  }
  if (j.round > 0 && j.progress.measured <= info.value("measured_before", 0.0) + 1e-9) {
    return end_setup(j, JobState::stalled, "round " + std::to_string(j.round) + " measured nothing new; " + attention + summary);
  }
  // Issue 15: a replanning round that delivered under 20 % of its prediction is not repeated. The rows it
  // aimed at are not where, or not as, the rough model says, and the next plan would aim at them alike
  // (bench_loop: such rounds went on realizing 7-20 % while adding tens of views).
  if (replan_fell_short(infos, j.progress.measured, j.rough->total_area_mm2)) {
    const json g = round_gains(infos, j.progress.measured, j.rough->total_area_mm2).back();
    return end_setup(j, JobState::stalled, "round " + std::to_string(j.round) + " realized " + fmt(g.at("realized_gain_mm2").get<double>(), 1) +
                                     " of the " + fmt(g.at("predicted_gain_mm2").get<double>(), 1) +
                                     " mm2 it predicted (under 20 %): the loop stops rather than repeat it; " + attention + summary);
  }
  // A stall found while replanning names them too.
  return replan(j, measured_now, fails, retired, n_retired, open, attention + summary, stop);
}

/// The next round of the setup: a plan for the open rows (retired ones left out, failed ones down-weighted),
/// journalled; or the end when it gains nothing or too little per view.
std::optional<JobState> JobRunner::replan(Job& j, const std::vector<std::uint8_t>& measured_now, const std::vector<std::uint8_t>& fails,
                                          const std::vector<std::uint8_t>& retired, std::size_t n_retired, std::size_t open,
                                          const std::string& summary, const std::atomic<int>& stop) {
  transition(j, JobState::replanning, std::to_string(open) + " rows left");
  sp::PlannerSettings replan = j.settings;  // without the between-view constraint (read_request)
  // The single shot leaves slivers under cover.min_view_gain_mm2 to the loop; a replan takes every view
  // that still gains jobs.min_gain_per_view_mm2 (weighted as below), and no view for less.
  replan.cover.min_view_gain = settings_.min_gain_per_view_mm2;
  // Nothing can measure the unmeasurable rows and the retired ones failed too often: neither is chased.
  // A row that failed once weighs less, so no view is planned chiefly for it.
  std::vector<std::uint8_t> measured = measured_now;
  std::vector<double> weight_scale(measured.size(), 1.0);
  for (std::size_t r = 0; r < measured.size(); ++r) {
    if (retired[r]) measured[r] = 1;
    else if (fails[r] > 0) weight_scale[r] = settings_.failed_row_weight;
  }
  // Open rows are mostly partly filled: each is predicted by samples of what it lacks (issue 15).
  std::vector<std::uint32_t> open_rows;
  for (std::uint32_t r = 0; r < measured.size(); ++r)
    if (!measured[r]) open_rows.push_back(r);
  const sp::RowFootprints footprints =
      settings_.footprint_samples > 0 ? j.coverage->open_footprints(open_rows, static_cast<std::size_t>(settings_.footprint_samples))
                                      : sp::RowFootprints{};
  sp::ViewPlan p = plan_or_stop([&] {
    // The object rests as the setup's first round placed it: in setup 1 the configured or chosen orientation
    // (placed on the plate again, the same way), in a further setup exactly where its alignment found it.
    sp::CellModel resting = models_.cell;
    if (j.setup > 1) resting = resting_at(models_.cell, j.object, j.cell.object_on_table);
    else resting.object_on_table.linear() = j.cell.object_on_table.linear();
    return sp::plan_views(j.object, models_.sensor, j.spec, replan, j.rough_options, settings_.planner_threads,
                          &resting, &measured, &weight_scale, &stop, settings_.footprint_samples > 0 ? &footprints : nullptr);
  }, stop);
  if (p.views.empty()) {
    return end_setup(j, JobState::stalled, "replan adds nothing: " + summary);
  }
  const double gain_per_view = p.predicted_gain_mm2 / static_cast<double>(p.views.size());
  if (gain_per_view < settings_.min_gain_per_view_mm2) {
    return end_setup(j, JobState::stalled, "the next round would gain " + fmt(gain_per_view, 2) + " mm2 per view (" +
                                     std::to_string(p.views.size()) + " views), under jobs.min_gain_per_view_mm2 " +
                                     fmt(settings_.min_gain_per_view_mm2, 1) + ": " + summary);
  }
  json rinfo = round_info(j, p, j.round + 1, j.setup, measured);
  rinfo["retired_rows"] = n_retired;
  rinfo["footprint_rows"] = footprints.size();
  journal_.add_plan(j.id, j.round + 1, view_records(p), rinfo.dump());
  return std::nullopt;
}

JobState JobRunner::run(std::int64_t id, const std::atomic<int>& stop) {
  Job j;
  j.id = id;
  j.stop = &stop;
  j.progress.job = id;
  const JobRecord rec = journal_.job(id);
  j.progress.state = rec.state;
  if (finished(rec.state)) return rec.state;
  // Paused or faulted (before it started, or left so): only resume, which queues it again, makes it runnable.
  if (rec.state == JobState::paused || rec.state == JobState::faulted || rec.state == JobState::awaiting_operator) return rec.state;
  if (!read_request(j, rec)) return JobState::faulted;

  try {
    // Rounds 0, 1, ... are plan rounds; round -1 is the rough scan of a bounding-box job.
    auto round_plans = [&] {
      std::vector<std::int64_t> out;
      for (const auto& [plan, round] : journal_.plan_rounds(id))
        if (round >= 0) out.push_back(plan);
      return out;
    };
    if (j.request.bbox_mm) rough_scan(j, stop);
    if (round_plans().empty())
      if (const auto end = plan_first_round(j, stop)) return *end;
    restore(j, round_plans());
    // A further setup the operator confirmed (continue): explored and aligned, then planned, once.
    if (const auto pending = pending_setup(j.id)) {
      if (const auto end = start_setup(j, *pending, stop)) return *end;
      restore(j, round_plans());
    }
    while (true) {
      const auto plans = round_plans();
      const json info = execute_round(j, plans, stop);
      if (const auto end = close_or_replan(j, plans.back(), info, stop)) return *end;
    }
  } catch (const Interrupted& e) {
    positioner_.halt_all();
    if (e.why == StopRequest::abort) {
      finish(j, JobState::aborted, std::string("by request ") + e.what());
      return JobState::aborted;
    }
    if (e.why == StopRequest::pause) {
      transition(j, JobState::paused, e.what());
      return JobState::paused;
    }
    journal_.event(id, std::string("daemon stopping ") + e.what() + "; resumes at the first unfinished view");
    j.progress.event = "interrupted (daemon stopping)";
    report_(j.progress);
    return j.progress.state;
  } catch (const dr::DriverError& e) {
    // Faulted is not an end: the job resumes at its first unfinished view once the fault is cleared.
    positioner_.halt_all();
    j.progress.fault_axis = e.axis;
    j.progress.fault_kind = dr::to_string(e.kind);
    transition(j, JobState::faulted, e.what());
    return JobState::faulted;
  } catch (const std::exception& e) {
    positioner_.halt_all();
    j.progress.fault_kind = "job";
    transition(j, JobState::faulted, e.what());
    return JobState::faulted;
  }
}

}  // namespace scancell::daemon
