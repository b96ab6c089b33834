// A bounding-box job's rough scan (docs/rough-scan.md): exploration views of the table, fused into the rough
// model the job then plans from; and the exploration views any further setup executes the same way.
#include "daemon/job_runner_detail.hpp"

#include <filesystem>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "daemon/acquire.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/geometry/surface_distance.hpp"
#include "planner/placement.hpp"
#include "planner/reconstruction/fusion.hpp"
#include "planner/reconstruction/rough_scan.hpp"

namespace scancell::daemon {

using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace job_detail;

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
  // The fused surface stands off the true one by about jobs.fused_model_sigma_mm: the planner keeps its
  // margins against a rough model's error on every row (rough_model_carries_error, docs/planner.md).
  j.rough_options.surface_error_mm = settings_.fused_model_sigma_mm;
  journal_.event(j.id, "rough model: planned as off the true surface by " + fmt(j.rough_options.surface_error_mm, 2) +
                           " mm (jobs.fused_model_sigma_mm): the planner's margins hold on every row");
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

}  // namespace scancell::daemon
