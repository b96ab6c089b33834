// Further setups of a job (issue 20): which resting pose measures what this setup could not, the wait for the
// operator, the exploration of the part as put down, its alignment to the model so far, and the setup's plan.
#include "daemon/job_runner_detail.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "common/json_matrix.hpp"
#include "daemon/job_product.hpp"
#include "daemon/job_result.hpp"
#include "planner/placement.hpp"
#include "planner/reconstruction/setup_alignment.hpp"
#include "planner/sim/verify.hpp"

namespace scancell::daemon {

using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace job_detail;

namespace {

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
  const sp::PlannerSettings& settings = j.settings;  // without the between-view constraint (read_request)
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

Eigen::Isometry3d JobRunner::actual_placement(const Job& j, int setup, const Eigen::Isometry3d& asked) const {
  return sim_operator_error(j.id, setup, settings_.sim_placement_error_mm, settings_.sim_placement_error_rad) * asked;
}

}  // namespace scancell::daemon
