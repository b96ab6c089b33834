#include "daemon/job_runner.hpp"
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
namespace {

using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using Clock = std::chrono::steady_clock;


std::string fmt(double v, int digits = 4) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

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

/// Simulation: how the simulated operator puts the part down in setup `setup` of job `job`, against what was
/// asked: a turn about the table axis and a shift on the plate, uniform within ± the configured bounds and
/// the same on every run of the job (a resume re-places it identically).
Eigen::Isometry3d sim_operator_error(std::int64_t job, int setup, double mm, double rad) {
  std::mt19937_64 rng(0x5e7u ^ (static_cast<std::uint64_t>(job) * 0x9E3779B97F4A7C15ull) ^ static_cast<std::uint64_t>(setup));
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double dx = mm * u(rng), dy = mm * u(rng), turn = rad * u(rng);
  Eigen::Isometry3d e = Eigen::Isometry3d::Identity();
  e.linear() = Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  e.translation() = Eigen::Vector3d(dx, dy, 0.0);
  return e;
}

Eigen::Isometry3d pose_from(const json& a, const std::string& what) {
  return Eigen::Isometry3d(scancell::matrix4_from_row_major(a, what));
}

/// A 3×3 rotation written by row_major_json; DataError naming `what` unless it is 9 finite numbers.
Eigen::Matrix3d rotation_from(const json& a, const std::string& what) {
  if (!a.is_array() || a.size() != 9) throw scancell::DataError(what + ": needs 9 numbers (row major)");
  Eigen::Matrix3d m;
  for (int k = 0; k < 9; ++k) {
    if (!a[k].is_number() || !std::isfinite(a[k].get<double>())) throw scancell::DataError(what + "[" + std::to_string(k) + "]: must be a finite number");
    m(k / 3, k % 3) = a[k].get<double>();
  }
  return m;
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

/// Which side the operator is to put down, for people: the object-frame direction that faces the plate.
std::string down_side(const Eigen::Vector3d& down) {
  int axis = 0;
  down.cwiseAbs().maxCoeff(&axis);
  const char* names[] = {"x", "y", "z"};
  char b[160];
  if (std::abs(down[axis]) > 0.98)
    std::snprintf(b, sizeof b, "its %s%s side down", down[axis] < 0 ? "-" : "+", names[axis]);
  else
    std::snprintf(b, sizeof b, "the side facing (%.2f, %.2f, %.2f) of the object frame down", down.x(), down.y(), down.z());
  return b;
}

}  // namespace

struct JobRunner::Job {
  std::int64_t id = 0;
  const std::atomic<int>* stop = nullptr;  // the run's stop request (pause, abort, shutdown)
  JobRequest request;
  sp::ModelSpec spec;
  sp::PlannerSettings settings;
  sp::RoughModelOptions rough_options;
  sp::TriangleMesh object;          // rough model input, mm, object frame
  std::optional<sp::RoughModel> rough;
  std::unique_ptr<sp::MeasuredCoverage> coverage;
  std::unique_ptr<sp::ModelCloud> cloud;  // what views register to: the rough model, then the registered views
  std::unique_ptr<ScanHead> head;
  sp::CellModel cell;               // with the object's placement on the table
  sp::TriangleMesh truth_table;     // simulation, bounding-box jobs: the object as it stands on the table
  json rough_quality;               // simulation, bounding-box jobs: the fused rough model against the truth
  json placement;                   // the resting-pose choice of round 0, when placement was auto
  sp::TriangleMesh truth_object;    // simulation: the object on the table, in the plan's object frame
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

void JobRunner::note_lost_profiles(Job& j, std::int64_t plan, int view, const sp::RangeImage& img,
                                   const std::vector<std::uint32_t>& predicted) {
  auto passed = rows_passed_without_profile(img, j.rough->points, predicted);
  if (!passed.empty()) j.excused[plan][view] = std::move(passed);
}

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

json JobRunner::next_setup(Job& j) {
  // Issue 20, first part: which way to turn the object so that the cell measures what this setup could not.
  // The operator's turn (awaiting_operator, continue, alignment) is not built yet: the result says what to do.
  try {
    const std::vector<std::uint8_t> measured = j.coverage->measured_rows();
    const sp::NextSetup n = sp::plan_next_setup(j.object, models_.sensor, j.spec, j.settings, j.rough_options,
                                                settings_.planner_threads, models_.cell, j.cell.object_on_table.linear(), measured,
                                                j.stop);
    journal_.event(j.id, "next setup: " + n.reason);
    json out = {{"reason", n.reason}, {"unmeasured_area_mm2", n.unmeasured_area_mm2}, {"poses_planned", n.options.size()}};
    if (n.pose < 0) return out;
    const Eigen::Vector3d down = n.rest.poses[n.pose].down_object;
    out["resting_pose"] = n.pose + 1;
    out["down_object"] = {down.x(), down.y(), down.z()};
    out["object_to_table_row_major"] = row_major_json(n.object_to_table);
    out["predicted_gain_mm2"] = n.predicted_gain_mm2;
    out["views"] = n.views;
    // The picture: the rough model turned into that pose (seen from ±X, ±Y, ±Z of the table; -Z is what rests
    // on the plate), measured grey, still unmeasured red.
    sp::TriangleMesh turned = j.rough->mesh();
    for (auto& v : turned.vertices) v = n.object_to_table * v;
    const auto png = settings_.jobs_dir / std::to_string(j.id) / "next_setup.png";
    std::filesystem::create_directories(png.parent_path());
    const std::string title = "job " + std::to_string(j.id) + ", next setup: rest the part with " + down_side(down) + " (resting pose " +
                              std::to_string(n.pose + 1) + ")\nseen from the table's axes (from -Z: what rests on the plate); " +
                              fmt(n.predicted_gain_mm2, 0) + " of the " + fmt(n.unmeasured_area_mm2, 0) + " mm2 left predicted in " +
                              std::to_string(n.views) + " views";
    if (const std::string why = sp::write_coverage_picture(turned, measured, title, png); !why.empty()) out["picture_error"] = why;
    out["picture"] = png.string();
    return out;
  } catch (const scancell::PlanCancelled& e) {
    // A stop (pause, abort, shutdown) while the advice is planned: the job's outcome stands without it, and
    // the daemon does not wait for the planner.
    journal_.event(j.id, std::string("next setup not planned: ") + e.what());
    return json{{"error", std::string("not planned: a stop was requested while planning it (") + e.what() + ")"}};
  } catch (const std::exception& e) {
    return json{{"error", e.what()}};  // the job's outcome stands; the advice failed and says why
  }
}

JobState JobRunner::end_setup(Job& j, JobState state, const std::string& cause) {
  if (j.setup >= j.max_setups || j.request.bbox_mm || settings_.next_setup_min_area_mm2 <= 0.0) {
    finish(j, state, cause);
    return state;
  }
  const RowTally t = tally_unmeasured(*j.rough, j.coverage->unmeasured_rows(), j.unmeasurable);
  if (t.unmeasured_area < settings_.next_setup_min_area_mm2) {
    finish(j, state, cause);
    return state;
  }
  const json advice = next_setup(j);
  if (!advice.contains("resting_pose")) {
    finish(j, state, cause, &advice);
    return state;
  }
  // The next setup: the placement asked of the operator (the rough model in the advised resting pose, centred
  // on the plate like every placement) and the exploration views that will find the part as really put down.
  const int next = j.setup + 1;
  const Eigen::Matrix3d rotation = rotation_from(advice.at("object_to_table_row_major"), "next setup object_to_table_row_major");
  const Eigen::Isometry3d asked = sp::place_on_plate(j.object, rotation, models_.cell.object_on_table.translation());
  Eigen::AlignedBox3d box;
  for (const auto& v : j.object.vertices) box.extend(asked * v);
  sp::CellModel table_cell = models_.cell;
  table_cell.object_on_table = Eigen::Isometry3d::Identity();
  std::vector<std::string> skipped;
  std::vector<sp::ExplorationView> views;
  // The alignment needs a good part of the surface, not all of it: a part larger than the sensor's depth of
  // field is explored as the largest box that fits, centred on it (its middle is in range).
  Eigen::Vector3d size = box.sizes();
  const double fits = 0.95 * (models_.sensor.range_max_mm - models_.sensor.range_min_mm);
  if (size.norm() > fits) size *= fits / size.norm();
  try {
    views = sp::exploration_views(table_cell, models_.sensor, size, settings_.setup_exploration, &skipped);
  } catch (const std::exception& e) {
    finish(j, state, cause + "; a setup " + std::to_string(next) + " was advised but cannot be explored: " + e.what(), &advice);
    return state;
  }
  std::vector<std::string> poses;
  for (const auto& v : views) poses.push_back(json({{"axes", v.q}, {"scan_length_mm", v.scan_length_mm}}).dump());
  // Simulation: what this setup left, against the truth (the same verified m_v the result reports at the end).
  json truth_figures = json::object();
  {
    std::vector<sp::RangeImage> images;
    for (auto& v : load_job_views(journal_, j.id)) images.push_back(std::move(v.image));
    const bool with_truth = !images.empty() && !j.truth_object.vertices.empty() && all_have_truth(images);
    if (with_truth) truth_figures["verified_mv"] = sp::verify_images(j.truth_object, j.spec, images).mv;
  }
  const std::string instruction = "turn the part over: " + down_side(Eigen::Vector3d(advice.at("down_object")[0].get<double>(),
                                                                                     advice.at("down_object")[1].get<double>(),
                                                                                     advice.at("down_object")[2].get<double>())) +
                                  " (resting pose " + std::to_string(advice.at("resting_pose").get<int>()) + "), centred on the plate" +
                                  (advice.contains("picture") ? "; picture " + advice.at("picture").get<std::string>() : "") +
                                  "; then scancellctl continue " + std::to_string(j.id);
  journal_.add_plan(j.id, -next, poses,
                    json({{"setup", next},
                          {"setup_exploration", true},
                          {"asked_object_to_table", row_major_json(asked.matrix())},
                          {"advice", advice},
                          {"instruction", instruction},
                          {"previous_setup_end", {{"state", to_string(state)}, {"cause", cause}}},
                          {"measured_coverage_before", j.progress.measured},
                          {"previous_setup_truth", truth_figures},
                          {"skipped", skipped}})
                        .dump());
  journal_.set_result(j.id, json({{"state", "awaiting_operator"},
                                  {"setup", j.setup},
                                  {"next_setup_number", next},
                                  {"measured_coverage", j.progress.measured},
                                  {"instruction", instruction},
                                  {"next_setup", advice}})
                                .dump());
  transition(j, JobState::awaiting_operator, "setup " + std::to_string(j.setup) + " " + to_string(state) + " (measured " +
                                                 fmt(j.progress.measured) + " of the rough model); " + instruction);
  return JobState::awaiting_operator;
}

namespace {
/// The job's setups for the result: per setup the placement asked, how it was aligned and what it measured.
json setups_json(Journal& journal, std::int64_t job) {
  json out = json::array();
  auto plans = journal.plan_rounds(job);  // by round; a further setup's exploration (round -k) comes in journal order
  std::sort(plans.begin(), plans.end());
  for (const auto& [plan, round] : plans) {
    const json info = json::parse(journal.plan_info(plan));
    if (round <= -2) {
      // What the setup before left, in simulation against the truth.
      if (!out.empty() && info.contains("previous_setup_truth") && info.at("previous_setup_truth").contains("verified_mv"))
        out.back()["verified_mv_at_end"] = info.at("previous_setup_truth").at("verified_mv");
      out.push_back({{"setup", info.at("setup")},
                     {"resting_pose", info.at("advice").value("resting_pose", 0)},
                     {"asked_object_to_table_row_major", info.at("asked_object_to_table")},
                     {"measured_coverage_before", info.value("measured_coverage_before", 0.0)},
                     {"views", 0}});
    } else if (round >= 0) {
      if (out.empty()) out.push_back({{"setup", 1}, {"views", 0}});
      json& s = out.back();
      s["views"] = s["views"].get<int>() + static_cast<int>(journal.scans(plan).size());
      if (info.contains("alignment")) s["alignment"] = info.at("alignment");
      if (info.contains("object_on_table") && !s.contains("object_on_table_row_major")) s["object_on_table_row_major"] = info.at("object_on_table");
    }
  }
  return out;
}

/// What the executed views cost the cell at its real speeds (the plan's move and sweep times; the simulated
/// drives may run faster): the figure issue 15 compares with an oracle's plan.
json cell_time_json(Journal& journal, std::int64_t job) {
  double move_s = 0.0, scan_s = 0.0;
  for (const auto& [plan, round] : journal.plan_rounds(job))
    if (round >= 0)
      for (const auto& v : journal.views(plan))
        if (v.stored) {
          const json pj = json::parse(v.pose_json);
          move_s += pj.value("move_s", 0.0);
          scan_s += pj.value("scan_s", 0.0);
        }
  return {{"cell_time_s", move_s + scan_s}, {"cell_move_s", move_s}, {"cell_scan_s", scan_s}};
}

/// How the operator is to place the object (the simulated cell placed it so): the chosen pose's rotation and
/// why, with every option's figures in the round-0 plan info.
json placement_json(const json& placement) {
  const json& chosen = placement.at("options").at(placement.at("chosen").get<int>() - 1);
  return {{"reason", placement.at("reason")},
          {"resting_pose", chosen.at("resting_pose")},
          {"object_to_table_row_major", chosen.at("object_to_table_row_major")},
          {"options", placement.at("options").size()}};
}

}  // namespace

JobRunner::Product JobRunner::write_product(const Job& j, const std::vector<StoredView>& stored, json& result) {
  // Every spec-compliant registered sample, whatever the end (an aborted job keeps what it measured). A
  // failure to write it is reported in the result, not hidden, and does not undo the job.
  Product out;
  const auto cloud = settings_.jobs_dir / std::to_string(j.id) / "cloud.ply";
  try {
    const CloudSummary& c = out.cloud.emplace(write_job_cloud(stored, j.id, j.spec, cloud, true, settings_.cloud_spacing_mm));
    result["cloud"] = cloud.string();
    result["cloud_points"] = c.points;
    const auto model = cloud.parent_path() / "model.ply";
    const ModelSummary& m = out.model.emplace(write_job_model(c, j.spec, model));
    result["model"] = model.string();
    result["model_triangles"] = m.triangles;
    result["model_open_edges"] = m.boundary_edges;
    result["model_voxel_mm"] = m.voxel_mm;
  } catch (const std::exception& e) {
    result["product_error"] = e.what();
  }
  return out;
}

void JobRunner::rows_into(Job& j, JobState state, const json* advice, json& result) {
  const std::vector<std::uint32_t> rows = j.coverage->unmeasured_rows();
  const RowTally t = tally_unmeasured(*j.rough, rows, j.unmeasurable);
  result["rough_area_mm2"] = j.rough->total_area_mm2;
  result["unmeasured_rows"] = rows.size();
  result["unmeasured_area_mm2"] = t.unmeasured_area;
  result["unmeasurable_rows"] = j.unmeasurable.size();  // no candidate view of this cell measures them
  result["open_rows"] = t.open;                        // measurable by the plan's estimate, not measured, seen surface
  result["open_area_mm2"] = t.open_area;
  if (!j.rough->hypothetical.empty()) {
    result["hypothetical_rows"] = std::count(j.rough->hypothetical.begin(), j.rough->hypothetical.end(), 1);  // the rough scan's guesses
    result["hypothetical_unmeasured_rows"] = t.hypothetical;  // of those, not measured (incl. unmeasurable)
    result["hypothetical_unmeasured_area_mm2"] = t.hypothetical_area;
  }
  if (advice) result["next_setup"] = *advice;
  else if (state != JobState::aborted && settings_.next_setup_min_area_mm2 > 0.0 && t.unmeasured_area >= settings_.next_setup_min_area_mm2 &&
           !j.object.vertices.empty())
    result["next_setup"] = next_setup(j);
  const auto dir = settings_.jobs_dir / std::to_string(j.id);
  result["unmeasured_file"] = write_unmeasured_rows(*j.rough, rows, dir).string();
  // The closed loop's account: what each round predicted and delivered, and the rows it gave up on.
  const std::vector<json> infos = round_infos(j);
  if (!infos.empty()) {
    std::vector<std::uint8_t> measured = j.coverage->measured_rows();
    for (auto r : j.unmeasurable) measured[r] = 1;
    result.update(closed_loop_account(*j.rough, infos, measured, j.progress.measured, settings_.retire_after_failures, dir));
  }
}

void JobRunner::report_into(const Job& j, const Product& product, json& result) {
  // The cloud and the model against the reference: the submitted mesh (a bounding-box job has none but, in
  // simulation, the object on the table).
  const bool bbox = j.request.bbox_mm.has_value();
  const sp::TriangleMesh& reference = bbox ? j.truth_object : j.object;
  if (!product.cloud || !product.model || reference.triangles.empty()) return;
  json coverage;
  for (const char* k : {"measured_coverage", "estimated_coverage", "verified_mv", "rough_area_mm2", "unmeasured_area_mm2",
                        "unmeasurable_rows", "open_area_mm2"})
    if (result.contains(k)) coverage[k] = result[k];
  try {
    const auto file = settings_.jobs_dir / std::to_string(j.id) / "report.json";
    const json r = write_job_report(file, j.id, j.spec, reference, bbox ? j.request.truth : j.request.mesh,
                                    bbox ? "simulation truth (the object on the table)" : "submitted mesh", *product.cloud,
                                    *product.model, coverage);
    result["report"] = file.string();
    result["cloud_deviation_rms_mm"] = r["cloud"]["rms_mm"];
    result["model_deviation_p95_mm"] = r["model"]["p95_abs_mm"];
    if (r.contains("deviation_png")) result["deviation_png"] = r["deviation_png"];
    if (r.contains("deviation_png_error")) result["deviation_png_error"] = r["deviation_png_error"];
  } catch (const std::exception& e) {
    result["report_error"] = e.what();
  }
}

void JobRunner::finish(Job& j, JobState state, const std::string& cause, const json* advice) {
  json result = {{"state", to_string(state)},
                 {"rounds", j.round + 1},
                 {"measured_coverage", j.progress.measured},
                 {"estimated_coverage", j.estimated_total}};
  int views = 0;
  for (const auto& [plan, round] : journal_.plan_rounds(j.id))
    if (round >= 0) views += static_cast<int>(journal_.scans(plan).size());  // the rough scan's are not views
  // The stored views that count, read once: for the product and, in simulation, the ground-truth checks.
  std::vector<StoredView> stored = load_job_views(journal_, j.id);
  const Product product = views > 0 ? write_product(j, stored, result) : Product{};
  if (views > 0) {
    // What the product holds, and what it does not: a view whose registration failed is stored but left out.
    result["product_views"] = stored.size();
    if (static_cast<std::size_t>(views) > stored.size())
      result["product_note"] = std::to_string(static_cast<std::size_t>(views) - stored.size()) + " of " + std::to_string(views) +
                               " views are not in the cloud or the model: their registration failed (the journal's events name each)";
  }
  std::vector<sp::RangeImage> images;
  if (state != JobState::aborted)
    for (auto& v : stored) images.push_back(std::move(v.image));
  stored.clear();
  result["views"] = views;
  result.update(cell_time_json(journal_, j.id));
  if (j.max_setups > 1) result["setups"] = setups_json(journal_, j.id);
  if (!j.rough_quality.is_null()) result["rough_model"] = j.rough_quality;
  if (!j.placement.is_null()) result["placement"] = placement_json(j.placement);
  if (j.rough && j.coverage) rows_into(j, state, advice, result);
  // Simulation: the checks against the object on the table. Ground truth exists only where the scanner is
  // simulated (in process, or sim_gige with the device's truth joined beside the wire): a real scanner's
  // images carry none, and the checks that need the true hit points are skipped.
  const bool with_truth = all_have_truth(images);
  if (!with_truth && !j.truth_object.vertices.empty())
    result["ground_truth_checks"] = "not run: the scans carry no simulation truth (the scanner is a device on the wire)";
  if (state != JobState::aborted && !images.empty() && !j.truth_object.vertices.empty() && with_truth)
    result.update(simulation_truth_checks(images, j.rough ? &*j.rough : nullptr, j.spec, settings_.coverage, j.truth_object,
                                          j.request.truth.empty() ? j.request.mesh : j.request.truth,
                                          settings_.jobs_dir / std::to_string(j.id)));
  report_into(j, product, result);  // the inspection report (issue 19)
  journal_.set_result(j.id, result.dump());
  transition(j, state, cause);
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

Eigen::Isometry3d JobRunner::actual_placement(const Job& j, int setup, const Eigen::Isometry3d& asked) const {
  return sim_operator_error(j.id, setup, settings_.sim_placement_error_mm, settings_.sim_placement_error_rad) * asked;
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
  std::size_t open_retired = 0;
  for (auto r : j.coverage->unmeasured_rows())
    open_retired += retired[r] && (j.rough->hypothetical.empty() || !j.rough->hypothetical[r]);
  if (open_retired == open && (guessed == 0 || j.round >= 1)) {
    return end_setup(j, JobState::stalled, std::to_string(n_retired) + " rows (" + fmt(retired_area, 1) + " mm2) need attention: predicted measurable by " +
                                     std::to_string(settings_.retire_after_failures) +
                                     " rounds, or by a replanning round that realized under 20 % of its prediction, and not measured; " + summary);
  }
  if (j.round - j.setup_first_round + 1 >= settings_.max_rounds) {
    return end_setup(j, JobState::stalled, "after " + std::to_string(j.round - j.setup_first_round + 1) + " rounds" +
                                              (j.setup > 1 ? " of setup " + std::to_string(j.setup) : "") + ": " + summary);
  }
  if (j.round > 0 && j.progress.measured <= info.value("measured_before", 0.0) + 1e-9) {
    return end_setup(j, JobState::stalled, "round " + std::to_string(j.round) + " measured nothing new; " + std::to_string(n_retired) +
                                     " rows (" + fmt(retired_area, 1) + " mm2) need attention: " + summary);
  }
  // Issue 15: a replanning round that delivered under 20 % of its prediction is not repeated. The rows it
  // aimed at are not where, or not as, the rough model says, and the next plan would aim at them alike
  // (bench_loop: such rounds went on realizing 7-20 % while adding tens of views).
  if (replan_fell_short(infos, j.progress.measured, j.rough->total_area_mm2)) {
    const json g = round_gains(infos, j.progress.measured, j.rough->total_area_mm2).back();
    return end_setup(j, JobState::stalled, "round " + std::to_string(j.round) + " realized " + fmt(g.at("realized_gain_mm2").get<double>(), 1) +
                                     " of the " + fmt(g.at("predicted_gain_mm2").get<double>(), 1) +
                                     " mm2 it predicted (under 20 %): the loop stops rather than repeat it; " + std::to_string(n_retired) +
                                     " rows (" + fmt(retired_area, 1) + " mm2) need attention: " + summary);
  }
  return replan(j, measured_now, fails, retired, n_retired, open, summary, stop);
}

/// The next round of the setup: a plan for the open rows (retired ones left out, failed ones down-weighted),
/// journalled; or the end when it gains nothing or too little per view.
std::optional<JobState> JobRunner::replan(Job& j, const std::vector<std::uint8_t>& measured_now, const std::vector<std::uint8_t>& fails,
                                          const std::vector<std::uint8_t>& retired, std::size_t n_retired, std::size_t open,
                                          const std::string& summary, const std::atomic<int>& stop) {
  transition(j, JobState::replanning, std::to_string(open) + " rows left");
  sp::PlannerSettings replan = j.settings;
  // Later rounds go after the leftovers only; their views register to the model through the rows they
  // share with it, not through each other, so the between-view registration constraint is dropped.
  if (replan.cover.mode == sp::CoverMode::constrained) replan.cover.mode = sp::CoverMode::greedy;
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

void JobRunner::rough_scan(Job& j, const std::atomic<int>& stop) {
  // The table frame is the object frame of the rough scan: the rough model comes out standing on the table.
  sp::CellModel table_cell = models_.cell;
  table_cell.object_on_table = Eigen::Isometry3d::Identity();
  {
    // Simulation: the object stands centred on the turntable, its base on the table top.
    j.truth_table = load_object(j.request.truth, j.request.fit_mm);
    const Eigen::Isometry3d place = sp::place_on_plate(j.truth_table, Eigen::Matrix3d::Identity());
    for (auto& v : j.truth_table.vertices) v = place * v;
  }
  const auto dir = settings_.jobs_dir / std::to_string(j.id);
  const auto rough_file = dir / "rough.off";
  std::optional<std::int64_t> plan;
  for (const auto& [p, round] : journal_.plan_rounds(j.id))
    if (round == -1) plan = p;
  if (!plan) {
    transition(j, JobState::rough_scanning);
    std::vector<std::string> skipped;
    const auto views = sp::exploration_views(table_cell, models_.sensor, *j.request.bbox_mm, settings_.rough_scan, &skipped);
    std::vector<std::string> poses;
    for (const auto& v : views) poses.push_back(json({{"axes", v.q}, {"scan_length_mm", v.scan_length_mm}}).dump());
    plan = journal_.add_plan(j.id, -1, poses, json({{"rough_scan", true}, {"skipped", skipped}}).dump());
    for (const auto& s : skipped) journal_.event(j.id, "rough scan: skipped " + s);
  }
  if (!std::filesystem::exists(rough_file)) {
    if (j.progress.state != JobState::rough_scanning) transition(j, JobState::rough_scanning, "resuming");
    // The scanner sees the table too: its samples carve the space above it (the fusion's floor keeps the
    // table itself out of the model), so the table's own triangles give samples here.
    explore(j, *plan, table_cell, sp::with_fixtures(j.truth_table, table_cell), "rough scan", stop);
    // Fuse what the exploration saw; what it did not see closes conservatively (hypothetical).
    sp::FusionOptions fo = settings_.rough_scan.fusion;
    fo.floor_z_mm = 0.0;
    sp::TsdfVolume volume(sp::exploration_bounds(*j.request.bbox_mm), fo);
    for (const auto& s : journal_.scans(*plan)) volume.integrate(sp::range_image_from_ply(journal_.read_scan(s), s.file));
    const sp::FusedModel fused = volume.extract();
    if (fused.mesh.triangles.empty()) throw scancell::DataError("rough scan: the fused volume holds no surface (is the object on the table?)");
    std::size_t guessed = 0;
    for (auto h : fused.hypothetical) guessed += h;
    std::filesystem::create_directories(dir);
    // The flags first: rough.off's existence says the rough scan is complete.
    sp::write_flagged_vertices(fused.mesh, fused.hypothetical, (dir / "rough.hypothetical.xyz").string());
    sp::write_off(fused.mesh, rough_file.string());
    journal_.event(j.id, "rough model: " + std::to_string(fused.mesh.vertices.size()) + " vertices, " + std::to_string(guessed) +
                             " hypothetical (unseen, closed conservatively), voxel " + fmt(volume.voxel_mm(), 2) + " mm -> " + rough_file.string());
  }
  j.object = sp::load_mesh(rough_file);
  // Which rows of the rough model are guesses (unseen space closed conservatively): the planner plans them
  // like any other, the verdict treats them apart.
  const auto flags = dir / "rough.hypothetical.xyz";
  if (std::filesystem::exists(flags)) j.rough_options.vertex_hypothetical = sp::read_flagged_vertices(j.object, flags.string());
  else journal_.event(j.id, "rough model: no " + flags.string() + " (a job from before the flags were kept): every row counts as seen");
  // Simulation: the fused rough model against the object really on the table — its seen part, and the
  // whole with its guesses.
  if (!j.truth_table.vertices.empty()) {
    std::vector<std::uint8_t> seen(j.object.vertices.size(), 1);
    for (std::size_t v = 0; v < seen.size() && v < j.rough_options.vertex_hypothetical.size(); ++v) seen[v] = !j.rough_options.vertex_hypothetical[v];
    const sp::SurfaceComparison all = sp::compare_surfaces(j.object, j.truth_table);
    const sp::SurfaceComparison part = sp::compare_surfaces(j.object, j.truth_table, seen);
    j.rough_quality = {{"hausdorff_mm", all.hausdorff_mm},
                       {"rough_to_fine_max_mm", all.model_to_truth_max_mm},
                       {"fine_to_rough_max_mm", all.truth_to_model_max_mm},
                       {"fine_to_rough_mean_mm", all.truth_to_model_mean_mm},
                       {"seen_rough_to_fine_max_mm", part.model_to_truth_max_mm},
                       {"seen_rough_to_fine_mean_mm", part.model_to_truth_mean_mm},
                       {"seen_normal_error_mean_rad", part.normal_error_mean_rad},
                       {"seen_normal_error_p95_rad", part.normal_error_p95_rad},
                       {"seen_vertices", part.model_vertices},
                       {"vertices", j.object.vertices.size()}};
    journal_.event(j.id, "rough model vs the object on the table: Hausdorff " + fmt(all.hausdorff_mm, 2) + " mm (fine to rough " +
                             fmt(all.truth_to_model_max_mm, 2) + " mm at most, " + fmt(all.truth_to_model_mean_mm, 3) +
                             " mm mean); seen part within " + fmt(part.model_to_truth_max_mm, 2) + " mm (" + fmt(part.model_to_truth_mean_mm, 3) +
                             " mm mean), normals " + fmt(part.normal_error_mean_rad * 180.0 / M_PI, 1) + "° mean, " +
                             fmt(part.normal_error_p95_rad * 180.0 / M_PI, 1) + "° at the 95th percentile");
  }
}

void JobRunner::explore(Job& j, std::int64_t plan, const sp::CellModel& table_cell, const sp::TriangleMesh& scene,
                        const std::string& what, const std::atomic<int>& stop) {
  const auto views = journal_.views(plan);
  j.progress.views = static_cast<int>(views.size());
  auto head = heads_(scene, scene.triangles.size(), table_cell);
  for (const auto& v : views) {
    if (v.stored) continue;
    const auto why = static_cast<StopRequest>(stop.load());
    if (why != StopRequest::none) throw Interrupted(why, "before " + what + " view " + std::to_string(v.index + 1));
    const json pj = json::parse(v.pose_json);
    j.progress.view = v.index + 1;
    const std::string label = what + " " + std::to_string(v.index + 1) + "/" + std::to_string(views.size());
    Acquisition got = acquire_view(positioner_, *head, table_cell, models_.sensor, pj.at("axes").get<std::vector<double>>(),
                                         pj.at("scan_length_mm").get<double>(), settings_, stop, [&](const std::string& step) {
                                           j.progress.event = label + ": " + step;
                                           report_(j.progress);
                                         });
    got.image.job = j.id;
    journal_.store_scan(plan, v.index, sp::range_image_to_ply(got.image), what);
    journal_.event(j.id, label + " stored: " + std::to_string(got.image.valid_count()) + " samples");
  }
}

std::optional<std::int64_t> JobRunner::pending_setup(std::int64_t job) {
  // Plan ids grow as plans are journalled: a further setup's exploration is pending until a plan round
  // comes after it (the setup's first).
  std::int64_t exploration = 0, latest_round = 0;
  for (const auto& [plan, round] : journal_.plan_rounds(job)) {
    if (round <= -2) exploration = std::max(exploration, plan);
    else if (round >= 0) latest_round = std::max(latest_round, plan);
  }
  if (exploration > latest_round) return exploration;
  return std::nullopt;
}

std::optional<JobState> JobRunner::start_setup(Job& j, std::int64_t plan, const std::atomic<int>& stop) {
  const json info = json::parse(journal_.plan_info(plan));
  const int setup = info.at("setup").get<int>();
  const std::string name = "setup " + std::to_string(setup);
  const Eigen::Isometry3d asked = pose_from(info.at("asked_object_to_table"), "plan info asked_object_to_table");
  sp::CellModel table_cell = models_.cell;
  table_cell.object_on_table = Eigen::Isometry3d::Identity();
  // 1. Exploration of the part as the operator put it down (in simulation: as asked, off by the simulated
  // operator's error), in the table frame.
  transition(j, JobState::rough_scanning, name + ": exploring the part as put down (" + std::to_string(journal_.views(plan).size()) + " views)");
  sp::TriangleMesh on_table = j.truth_object;
  const Eigen::Isometry3d actual = actual_placement(j, setup, asked);
  for (auto& v : on_table.vertices) v = actual * v;
  explore(j, plan, table_cell, sp::with_fixtures(on_table, table_cell), name + " exploration", stop);
  // 2. Alignment to the model so far; a refusal ends the job with what the setups before measured.
  json alignment;
  const auto estimated = align_to_model(j, name, plan, asked, actual, alignment);
  if (!estimated) {
    finish(j, JobState::stalled, name + ": the part as put down could not be aligned to the model so far, so nothing of it was merged: " +
                                     alignment.at("why").get<std::string>() + "; what the setups before measured is kept");
    return JobState::stalled;
  }
  // 3. The setup's first plan.
  return plan_setup(j, setup, info, *estimated, alignment, stop);
}

std::optional<Eigen::Isometry3d> JobRunner::align_to_model(Job& j, const std::string& name, std::int64_t plan, const Eigen::Isometry3d& asked,
                                                           const Eigen::Isometry3d& actual, json& alignment) {
  // The samples go into the object frame as if the part lay exactly as asked; what lies within 1 mm of the
  // plate's top is the plate, not the part.
  const Eigen::Isometry3d to_nominal = asked.inverse();
  std::vector<Eigen::Vector3d> points, normals;
  bool simulated = true;  // every exploration image carries the simulated scanner's truth
  for (const auto& sc : journal_.scans(plan)) {
    const sp::RangeImage img = sp::range_image_from_ply(journal_.read_scan(sc), sc.file);
    simulated = simulated && img.has_truth();
    std::vector<Eigen::Vector3d> p, n;
    sp::image_points_normals(img, 2, p, n);
    for (std::size_t k = 0; k < p.size(); ++k)
      if (p[k].z() > 1.0) {
        points.push_back(to_nominal * p[k]);
        normals.push_back(to_nominal.linear() * n[k]);
      }
  }
  transition(j, JobState::planning, name + ": aligning " + std::to_string(points.size()) + " exploration samples to the model so far");
  if (!j.cloud) j.cloud = std::make_unique<sp::ModelCloud>(sp::ModelCloud::from_mesh(j.object, 1.0));
  sp::SetupAlignmentOptions ao = settings_.setup_alignment;
  ao.axis_point = to_nominal * Eigen::Vector3d::Zero();
  ao.axis_direction = to_nominal.linear() * Eigen::Vector3d::UnitZ();
  constexpr std::size_t kMinSamples = 100;
  const sp::SetupAlignmentResult a = points.size() < kMinSamples ? sp::SetupAlignmentResult{} : sp::align_setup(points, normals, *j.cloud, ao);
  alignment = {{"ok", a.ok},           {"samples", points.size()}, {"rms_mm", a.rms_mm},       {"overlap", a.overlap},
               {"turn_rad", a.turn_rad}, {"tilt_rad", a.tilt_rad},   {"shift_mm", a.shift_mm},   {"free_directions", a.free_directions},
               {"plate_conditioning", a.plate_conditioning}, {"ambiguous", a.ambiguous}};
  if (!a.ok) {
    alignment["why"] = points.size() < kMinSamples
                           ? "the exploration saw " + std::to_string(points.size()) + " samples of the part above the plate"
                           : a.why;
    journal_.event(j.id, name + ": alignment refused: " + alignment["why"].get<std::string>());
    return std::nullopt;
  }
  const Eigen::Isometry3d estimated = asked * a.correction.inverse();
  std::string truth;
  if (simulated) {
    // Simulation: how well the alignment found where the part really lies (at the part's centre).
    const Eigen::Isometry3d miss = estimated.inverse() * actual, error = actual * asked.inverse();
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& v : j.object.vertices) centre += v / static_cast<double>(j.object.vertices.size());
    alignment["sim_operator_shift_mm"] = error.translation().norm();
    alignment["sim_operator_turn_deg"] = Eigen::AngleAxisd(error.linear()).angle() * 180.0 / M_PI;
    alignment["sim_residual_mm"] = (miss * centre - centre).norm();
    alignment["sim_residual_deg"] = Eigen::AngleAxisd(miss.linear()).angle() * 180.0 / M_PI;
    truth = "; against the simulated placement off by " + fmt(alignment["sim_residual_mm"].get<double>(), 3) + " mm, " +
            fmt(alignment["sim_residual_deg"].get<double>(), 3) + "°";
  }
  journal_.event(j.id, name + ": aligned (" + std::to_string(points.size()) + " samples, residual " + fmt(a.rms_mm, 3) + " mm, turned " +
                           fmt(a.turn_rad * 180.0 / M_PI, 2) + "° and shifted " + fmt(a.shift_mm, 2) + " mm from the placement asked" +
                           truth + ")");
  return estimated;
}

/// A further setup's first plan: only what is still unmeasured, with the part where the alignment found it.
std::optional<JobState> JobRunner::plan_setup(Job& j, int setup, const json& exploration_info, const Eigen::Isometry3d& estimated,
                                              const json& alignment, const std::atomic<int>& stop) {
  const std::string name = "setup " + std::to_string(setup);
  const std::vector<std::uint8_t> measured = j.coverage->measured_rows();
  sp::PlannerSettings settings = j.settings;
  if (settings.cover.mode == sp::CoverMode::constrained) settings.cover.mode = sp::CoverMode::greedy;  // views register to the model
  const sp::CellModel placed = resting_at(models_.cell, j.object, estimated);
  const sp::ViewPlan p = plan_or_stop([&] {
    return sp::plan_views(j.object, models_.sensor, j.spec, settings, j.rough_options, settings_.planner_threads, &placed, &measured,
                          nullptr, &stop);
  }, stop);
  if (p.views.empty()) {
    finish(j, JobState::stalled, name + ": no view of the part in this pose measures what is left");
    return JobState::stalled;
  }
  int rounds = 0;
  for (const auto& [pl, round] : journal_.plan_rounds(j.id)) rounds += round >= 0;
  // Unmeasurable from here on: what no view of the part in this pose measures and no setup before did.
  std::vector<std::uint32_t> unmeasurable;
  for (auto r : p.cover.unmeasurable_rows)
    if (!measured[r]) unmeasurable.push_back(r);
  json rinfo = round_info(j, p, rounds, setup, measured);
  rinfo["asked_object_to_table"] = exploration_info.at("asked_object_to_table");
  rinfo["alignment"] = alignment;
  rinfo["unmeasurable_rows"] = unmeasurable;
  journal_.add_plan(j.id, rounds, view_records(p), rinfo.dump());
  return std::nullopt;
}

void JobRunner::execute_view(Job& j, std::int64_t plan, const ViewRecord& v, const std::atomic<int>& stop) {
  const auto t0 = Clock::now();
  const json pj = json::parse(v.pose_json);
  const double L = pj.at("scan_length_mm").get<double>();
  const auto q = pj.at("axes").get<std::vector<double>>();
  const sp::CellModel& cell = j.cell;
  if (q.size() != cell.axes.size())
    throw scancell::DataError("plan " + std::to_string(plan) + " view " + std::to_string(v.index) + ": " + std::to_string(q.size()) +
                        " axis targets for a cell of " + std::to_string(cell.axes.size()) + " axes");

  j.progress.view = v.index + 1;
  double remaining = 0.0;
  for (std::size_t k = static_cast<std::size_t>(v.index); k < j.planned_view_s.size(); ++k) remaining += j.planned_view_s[k];
  if (j.views_timed > 0 && j.planned_view_s.size() > static_cast<std::size_t>(v.index))
    remaining = j.view_seconds * static_cast<double>(j.planned_view_s.size() - static_cast<std::size_t>(v.index));
  j.progress.eta_s = remaining;

  const Acquisition got = acquire_view(positioner_, *j.head, cell, models_.sensor, q, L, settings_, stop, [&](const std::string& what) {
    trace_.mark(what);
    j.progress.event = "view " + std::to_string(v.index + 1) + "/" + std::to_string(j.progress.views) + ": " + what;
    report_(j.progress);
  });
  sp::RangeImage img = got.image;
  const int lost = got.lost_profiles;
  if (static_cast<std::size_t>(v.index) < j.view_rows.size())
    note_lost_profiles(j, plan, v.index, img, j.view_rows[static_cast<std::size_t>(v.index)]);

  // Register the view to the model before its coverage counts (thesis 1.1.4: the positioner's pose is not
  // good enough to trust the samples where it put them).
  std::string note, registration;
  trace_.mark("registering");  // the sweep is over: from here to "stored" the view exists only in memory
  if (j.cloud) {
    // Rotations about each profile's laser origin: a camera orientation error shears a line scan.
    const sp::IcpResult r = sp::register_scan(sp::scan_samples(img), *j.cloud, settings_.icp);
    if (r.ok) {
      // Against a fused rough model the correction is partly the model's own error: believe it as far as
      // the positioner is less certain than the model.
      const double weight = j.request.bbox_mm ? sp::correction_weight(cell.pose_error, models_.sensor.optimal_standoff_mm,
                                                                        settings_.fused_model_sigma_mm)
                                              : 1.0;
      sp::apply_correction(img, sp::scale_correction(r.correction, weight));
      registration = ", registered (samples moved " + fmt(r.moved_mean_mm, 3) + " mm on average, " + fmt(r.moved_max_mm, 3) +
                     " mm at most, turned " + fmt(Eigen::AngleAxisd(r.correction.linear()).angle() * 180.0 / M_PI, 3) + "°, residual " +
                     fmt(r.rms_mm, 3) + " mm" +
                     (r.free_directions ? ", " + std::to_string(r.free_directions) + " directions left as positioned" : "") +
                     (weight < 0.999 ? ", applied at " + fmt(weight, 2) + " against the rough model's own error" : "") + ")";
    } else {
      note = "registration failed: " + r.why;
      registration = ", " + note + "; not counted";
    }
  }
  // Store (durable before it counts), then update the measured coverage and the model views register to.
  trace_.mark("storing");
  img.job = j.id;
  journal_.store_scan(plan, v.index, sp::range_image_to_ply(img), note);
  trace_.mark("stored");
  if (note.empty()) {
    j.coverage->add(img);
    if (j.cloud) {
      std::vector<Eigen::Vector3d> p, n;
      sp::image_points_normals(img, 3, p, n);
      j.cloud->add(p, n);
    }
  }
  j.progress.measured = j.coverage->coverage();
  const double secs = seconds_since(t0);
  j.view_seconds = (j.view_seconds * j.views_timed + secs) / (j.views_timed + 1);
  ++j.views_timed;
  j.progress.eta_s = j.view_seconds * static_cast<double>(j.planned_view_s.size() - static_cast<std::size_t>(v.index) - 1);
  j.progress.event = "view " + std::to_string(v.index + 1) + "/" + std::to_string(j.progress.views) + " stored: " +
                     std::to_string(img.valid_count()) + " samples" + (got.fill_sweeps ? ", " + std::to_string(got.fill_sweeps) + " fill sweep" + (got.fill_sweeps > 1 ? "s" : "") + " took " +
                                                 std::to_string(got.filled_profiles) + " profiles"
                                           : "") +
                     (lost ? ", " + std::to_string(lost) + " profiles missed" +
                                 (settings_.fill_sweeps > 0 ? " after the fill sweeps (a loaded host or a lossy link: lower jobs.scan_speed_mm_s "
                                                              "or raise jobs.fill_sweeps)"
                                                            : " (jobs.fill_sweeps 0 keeps them missing)")
                            : "") +
                     registration + ", measured " + fmt(j.progress.measured) + " (" + fmt(secs, 2) + " s)";
  journal_.event(j.id, j.progress.event);
  report_(j.progress);
}

}  // namespace scancell::daemon
