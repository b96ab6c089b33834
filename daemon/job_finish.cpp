// A job's end: the result (rows, rounds, cell time, setups, placement), the product (cloud.ply, model.ply),
// the inspection report and, in simulation, the checks against the truth.
#include "daemon/job_runner_detail.hpp"

#include <algorithm>
#include <string>
#include <vector>

#include "daemon/job_product.hpp"
#include "daemon/job_result.hpp"

namespace scancell::daemon {

using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace job_detail;

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

}  // namespace scancell::daemon
