// The job's product against the truth (issue 19): on each shared mesh, scaled to 200 mm, the free-space plan
// (shipped settings, 5000 rough vertices) is executed by the virtual scanner (range noise on, no pose error:
// this measures the fusion, not the positioner), the product is built as a job builds it (cloud_ply, then
// fuse_model: OpenVDB signed distance, VolumeToMesh), and the model is compared with the true surface:
//   - model → truth: signed deviation of the model's vertices (mean, RMS, p95, max = one-sided Hausdorff)
//     and the share within 3 × the precision spec;
//   - the model's normals against the truth's: the angle between each model vertex's normal (area-weighted
//     from its triangles) and the normal of the true triangle closest to it, median and 95th percentile;
//   - truth → model, the seen part: the share of the fine vertices the views measured (verify_images) that
//     lie within 3 × the precision spec of the model;
//   - invented surface: model vertices farther than two voxels from every sample;
//   - time of the fusion (cloud_ply + fuse_model) and the process's peak memory after it (an upper bound on
//     the fusion's: plan, scans and verification run in the same process), the issue's ≤ 10 s and ≤ 2 GB.
//   bench_product [--meshes DIR] [--threads N] [--csv FILE]
#include <algorithm>
#include <cmath>
#include <tuple>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "bench/bench_common.hpp"
#include "planner/config.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/geometry/surface_distance.hpp"
#include "planner/plan.hpp"
#include "planner/reconstruction/inspection.hpp"
#include "planner/reconstruction/product.hpp"
#include "planner/reconstruction/registration.hpp"
#include "planner/sim/verify.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace sp = scancell::planner;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Row {
  std::string object;
  std::size_t views = 0, samples = 0, model_vertices = 0, invented = 0;
  double mv = 0.0, fuse_s = 0.0, peak_mb = 0.0;
  sp::DeviationStats model;   // model vertices against the truth
  double seen_within = 0.0;   // measured truth vertices within the tolerance of the model
  double normal_median_deg = 0.0, normal_p95_deg = 0.0;
  std::size_t boundary_edges = 0;
};

/// Angle (deg) between each model vertex's normal and the closest true triangle's: median and p95.
std::pair<double, double> normal_error_deg(const sp::TriangleMesh& model, const sp::TriangleMesh& truth) {
  std::vector<Eigen::Vector3d> vn(model.vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& t : model.triangles) {
    const Eigen::Vector3d n = (model.vertices[t[1]] - model.vertices[t[0]]).cross(model.vertices[t[2]] - model.vertices[t[0]]);
    for (int k = 0; k < 3; ++k) vn[t[k]] += n;  // area-weighted (|n| = twice the area)
  }
  const sp::SurfaceIndex index(truth);
  std::vector<double> angle;
  angle.reserve(vn.size());
  for (std::size_t i = 0; i < vn.size(); ++i) {
    if (vn[i].norm() == 0.0) continue;
    const sp::Triangle& t = truth.triangles[index.closest(model.vertices[i]).triangle];
    const Eigen::Vector3d n =
        (truth.vertices[t[1]] - truth.vertices[t[0]]).cross(truth.vertices[t[2]] - truth.vertices[t[0]]).normalized();
    angle.push_back(std::acos(std::clamp(vn[i].normalized().dot(n), -1.0, 1.0)) * 180.0 / M_PI);
  }
  if (angle.empty()) return {0.0, 0.0};
  auto rank = [&](double q) {
    const auto k = static_cast<std::ptrdiff_t>(std::ceil(q * static_cast<double>(angle.size()))) - 1;
    std::nth_element(angle.begin(), angle.begin() + k, angle.end());
    return angle[static_cast<std::size_t>(k)];
  };
  const double median = rank(0.5);
  return {median, rank(0.95)};
}

/// The plan, executed on the truth by the virtual scanner, fused, compared.
Row run(const std::string& name, const sp::TriangleMesh& truth, const sp::SensorModel& sensor, const sp::ModelSpec& spec,
        const sp::PlannerSettings& settings, int threads) {
  Row r;
  r.object = name;
  sp::RoughModelOptions rough;
  rough.target_vertices = 5000;
  const sp::ViewPlan plan = sp::plan_views(truth, sensor, spec, settings, rough, threads);
  r.views = plan.views.size();
  const sp::OcclusionScene scene(truth);
  std::vector<sp::ProductView> views;
  std::vector<sp::RangeImage> images;
  for (std::size_t k = 0; k < plan.views.size(); ++k) {
    sp::ScanOptions o;
    o.seed = sp::mix_seed(11, k);
    views.push_back({sp::virtual_scan(scene, sensor, sp::scan_pose(plan.views[k]), o), static_cast<int>(k), 0});
    images.push_back(views.back().image);
  }
  const sp::Verification v = sp::verify_images(truth, spec, images);
  r.mv = v.mv;

  const auto t = Clock::now();
  sp::CloudSummary cloud;
  (void)sp::cloud_ply(views, 0, spec, cloud, true);
  sp::ModelSummary ms;
  const sp::SurfaceMesh model = sp::fuse_model(cloud, spec, ms);
  r.fuse_s = scancell::seconds_since(t);
  r.peak_mb = scancell::bench::peak_rss_mb();  // the process's peak so far: an upper bound on the fusion's
  r.samples = cloud.compliant;
  r.model_vertices = model.mesh.vertices.size();
  r.boundary_edges = ms.boundary_edges;

  const double tol = 3.0 * spec.precision_mm;
  r.model = sp::signed_deviation(model.mesh.vertices, truth, tol);
  std::tie(r.normal_median_deg, r.normal_p95_deg) = normal_error_deg(model.mesh, truth);
  std::vector<Eigen::Vector3d> seen;
  for (std::size_t i = 0; i < truth.vertices.size(); ++i)
    if (v.measured[i]) seen.push_back(truth.vertices[i]);
  r.seen_within = seen.empty() ? 0.0 : sp::signed_deviation(seen, model.mesh, tol).within_tolerance;
  sp::ModelCloud samples;
  samples.add(cloud.positions, cloud.normals);
  for (const auto& p : model.mesh.vertices) r.invented += samples.nearest(p, 2.0 * ms.voxel_mm) < 0;
  return r;
}

}  // namespace

static int run_bench(int argc, char** argv) {
  std::string dir = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes", csv;
  int threads = 2;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--meshes") && i + 1 < argc) dir = argv[++i];
    else if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) csv = argv[++i];
    else {
      std::fprintf(stderr, "usage: bench_product [--meshes DIR] [--threads N] [--csv FILE]\n");
      return 2;
    }
  }
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
  const sp::SensorModel sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const sp::ModelSpec spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  const sp::PlannerSettings settings = sp::load_planner_settings(scancell::bench::shipped_settings_path());
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".off") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    std::fprintf(stderr, "bench_product: no .off mesh in %s\n", dir.c_str());
    return 1;
  }
  std::printf("scancell product benchmark: free-space plan (5000 rough vertices) executed by the virtual scanner (noise, no pose\n"
              "error), fused as a job fuses it, against the truth; 200 mm, thesis sensor and spec (tolerance 3 x %.3f mm), %d threads\n\n",
              spec.precision_mm, threads);
  std::printf("%-14s %5s %6s %9s %8s %9s %9s %9s %9s %7s %9s %8s %8s %8s %8s %8s %8s\n", "object", "views", "m_v", "samples", "model_v",
              "mean_mm", "rms_mm", "p95_mm", "max_mm", "in_tol", "seen_tol", "n50_deg", "n95_deg", "invented", "open_e", "fuse_s", "rss_MB");
  std::ofstream out;
  if (!csv.empty()) {
    out.open(csv);
    out << "object,views,verified_mv,samples,model_vertices,model_mean_mm,model_rms_mm,model_p95_abs_mm,model_max_abs_mm,"
           "model_within_tolerance,seen_truth_within_tolerance,normal_error_median_deg,normal_error_p95_deg,invented_vertices,open_edges,fuse_s,process_peak_rss_mb\n";
  }
  for (const auto& f : files) {
    sp::TriangleMesh m = sp::load_mesh(f.string());
    sp::apply_scale(m, sp::fit_scale(m, 200.0));
    const Row r = run(f.stem().string(), m, sensor, spec, settings, threads);
    std::printf("%-14s %5zu %6.4f %9zu %8zu %+9.4f %9.4f %9.4f %9.4f %7.4f %9.4f %8.2f %8.2f %8zu %8zu %8.2f %8.0f\n", r.object.c_str(),
                r.views, r.mv, r.samples, r.model_vertices, r.model.mean_mm, r.model.rms_mm, r.model.p95_abs_mm, r.model.max_abs_mm,
                r.model.within_tolerance, r.seen_within, r.normal_median_deg, r.normal_p95_deg, r.invented, r.boundary_edges, r.fuse_s,
                r.peak_mb);
    std::fflush(stdout);
    if (out)
      out << r.object << ',' << r.views << ',' << r.mv << ',' << r.samples << ',' << r.model_vertices << ',' << r.model.mean_mm << ','
          << r.model.rms_mm << ',' << r.model.p95_abs_mm << ',' << r.model.max_abs_mm << ',' << r.model.within_tolerance << ','
          << r.seen_within << ',' << r.normal_median_deg << ',' << r.normal_p95_deg << ',' << r.invented << ',' << r.boundary_edges << ',' << r.fuse_s << ',' << r.peak_mb << '\n';
  }
  return 0;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_product", [&] { return run_bench(argc, argv); });
}
