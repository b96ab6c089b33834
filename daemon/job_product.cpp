#include "daemon/job_product.hpp"

#include <cmath>
#include <ctime>
#include <sstream>

#include "planner/reconstruction/inspection.hpp"
#include "planner/reconstruction/surface_mesh.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;

std::vector<StoredView> load_job_views(Journal& journal, std::int64_t job) {
  std::vector<StoredView> out;
  for (const auto& [plan, round] : journal.plan_rounds(job)) {
    if (round < 0) continue;  // the rough scan: table frame, exploration only
    for (const auto& s : journal.scans(plan)) {
      if (!s.note.empty()) continue;  // does not count (its registration failed)
      out.push_back({sp::range_image_from_ply(journal.read_scan(s), s.file), s.view, round});
    }
  }
  return out;
}

CloudSummary write_job_cloud(const std::vector<StoredView>& views, std::int64_t job, const sp::ModelSpec& spec,
                             const std::filesystem::path& file, bool keep_samples, double spacing_mm) {
  CloudSummary sum;
  const std::string bytes = sp::cloud_ply(views, job, spec, sum, keep_samples, spacing_mm);
  std::filesystem::create_directories(file.parent_path());
  write_file_durably(file, bytes);
  return sum;
}

ModelSummary write_job_model(const CloudSummary& cloud, const sp::ModelSpec& spec, const std::filesystem::path& file) {
  ModelSummary sum;
  const sp::SurfaceMesh m = sp::fuse_model(cloud, spec, sum);
  std::filesystem::create_directories(file.parent_path());
  write_file_durably(file, sp::surface_ply(m));
  return sum;
}

namespace {

nlohmann::json stats_json(const sp::DeviationStats& d) {
  return {{"points", d.points},           {"mean_mm", d.mean_mm},       {"rms_mm", d.rms_mm},
          {"p95_abs_mm", d.p95_abs_mm},   {"max_abs_mm", d.max_abs_mm}, {"within_tolerance", d.within_tolerance}};
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

}  // namespace

nlohmann::json write_job_report(const std::filesystem::path& file, std::int64_t job, const sp::ModelSpec& spec,
                                const sp::TriangleMesh& reference, const std::string& reference_name,
                                const std::string& reference_kind, const CloudSummary& cloud, const ModelSummary& model,
                                const nlohmann::json& coverage) {
  const double tolerance = 3.0 * spec.precision_mm;
  const nlohmann::json r = {
      {"format", "scancell-inspection-report"},
      {"version", 1},
      {"job", job},
      {"date_utc", utc_now()},
      {"spec", {{"precision_mm", spec.precision_mm}, {"density_per_mm2", spec.density_per_mm2}}},
      {"reference", reference_name},
      {"reference_kind", reference_kind},
      {"sign", "+ outside the reference surface (along its outward normal), - inside"},
      {"tolerance_mm", tolerance},
      {"cloud", stats_json(sp::signed_deviation(cloud.positions, reference, tolerance))},
      {"model", stats_json(sp::signed_deviation(model.positions, reference, tolerance))},
      {"coverage", coverage}};
  std::filesystem::create_directories(file.parent_path());
  write_file_durably(file, r.dump(2) + "\n");
  return r;
}

}  // namespace scancell::daemon
