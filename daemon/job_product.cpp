#include "daemon/job_product.hpp"

#include <bit>
#include <cmath>
#include <cstring>
#include <ctime>
#include <sstream>

#include "common/binary.hpp"
#include "planner/reconstruction/inspection.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "planner/reconstruction/registration.hpp"
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
                             const std::filesystem::path& file, bool keep_samples) {
  CloudSummary sum;
  std::string body;
  for (const StoredView& v : views) {
    const sp::RangeImage& img = v.image;
    const std::vector<std::uint8_t> ok = sp::MeasuredCoverage::compliant_samples(img, spec);
    const sp::ScanSamples smp = sp::scan_samples(img);  // valid samples in sample order, with normals
    std::size_t k = 0;
    for (std::size_t q = 0; q < img.samples.size(); ++q) {
      if (!img.samples[q].valid()) continue;
      const std::size_t at = k++;
      if (!ok[q]) continue;
      const auto& p = img.samples[q].object_mm;
      const Eigen::Vector3d& n = smp.normals[at];
      for (int c = 0; c < 3; ++c) scancell::append_binary<float>(body, p[c]);
      for (int c = 0; c < 3; ++c) scancell::append_binary<float>(body, static_cast<float>(n[c]));
      scancell::append_binary<float>(body, img.samples[q].sigma_z_mm);
      scancell::append_binary<std::int32_t>(body, v.view);
      scancell::append_binary<std::int32_t>(body, v.round);
      ++sum.points;
      if (keep_samples) {
        sum.positions.push_back(p.cast<double>());
        sum.normals.push_back(n);
      }
    }
    ++sum.views;
  }
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\ncomment scancell registered cloud 1\ncomment job " << job
    << "\ncomment spec precision_mm " << spec.precision_mm << " density_per_mm2 " << spec.density_per_mm2
    << "\ncomment frame object mm\nelement vertex " << sum.points
    << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz"
       "\nproperty float sigma_z_mm\nproperty int view\nproperty int round\nend_header\n";
  std::filesystem::create_directories(file.parent_path());
  write_file_durably(file, h.str() + body);
  return sum;
}

ModelSummary write_job_model(const CloudSummary& cloud, const sp::ModelSpec& spec, const std::filesystem::path& file) {
  sp::SurfaceMeshOptions o;
  // Half the spec's sample spacing: the surface keeps what the specified density can resolve.
  o.voxel_mm = 0.5 / std::sqrt(spec.density_per_mm2);
  const sp::SurfaceMesh m = sp::mesh_from_oriented_points(cloud.positions, cloud.normals, o);
  ModelSummary sum;
  sum.vertices = m.mesh.vertices.size();
  sum.triangles = m.mesh.triangles.size();
  sum.voxel_mm = o.voxel_mm;
  sum.boundary_edges = sp::count_edges(m.mesh).open;
  sum.positions = m.mesh.vertices;
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
