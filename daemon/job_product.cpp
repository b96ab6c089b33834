#include "daemon/job_product.hpp"

#include <cmath>
#include <ctime>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "common/gnuplot.hpp"
#include "planner/reconstruction/inspection.hpp"
#include "planner/reconstruction/surface_mesh.hpp"
#include "planner/sim/verify.hpp"
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

/// deviation.png: the cloud's samples coloured by their signed deviation from the reference, from the front
/// and from behind, the colour bar spanning ± the tolerance (beyond it: the bar's end colours), titled with
/// the job, the reference, the date, the spec and the figures. At most 150,000 points are drawn (every k-th).
void write_deviation_png(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& deviation_mm,
                         double tolerance_mm, const std::string& title, const std::filesystem::path& png) {
  const ScratchDir dir("scancell-deviation-png");
  const std::size_t stride = std::max<std::size_t>(1, (points.size() + 149999) / 150000);
  {
    std::ofstream f(dir.path / "dev.dat");
    f.precision(6);
    for (std::size_t k = 0; k < points.size(); k += stride)
      f << points[k].x() << ' ' << points[k].y() << ' ' << points[k].z() << ' ' << deviation_mm[k] << '\n';
    if (!f.flush()) throw std::runtime_error("deviation picture: cannot write its data in " + dir.path.string());
  }
  std::ostringstream s;
  s << "set multiplot layout 1,2 title " << gnuplot_text(title) << " font ',11' noenhanced\n"
    << "set xlabel 'x (mm)'\nset ylabel 'y (mm)'\nset zlabel 'z (mm)' rotate parallel\nset view equal xyz\nset ticslevel 0\n"
    << "set palette defined (-1 '#2c5fb8', -0.33 '#7fb8e6', 0 '#2e9e44', 0.33 '#f0b44c', 1 '#c8302c')\n"
    << "set cbrange [" << -tolerance_mm << ":" << tolerance_mm << "]\n"
    << "set cblabel 'signed deviation (mm)'\n"
    << "set label 1 'colour: signed distance to the reference surface, + outside, - inside; the bar ends also hold "
       "everything beyond ±" << tolerance_mm << " mm (3 × the precision spec)' at screen 0.5,0.03 center font ',10'\n"
    << "plot_it = \"splot " << gnuplot_quoted((dir.path / "dev.dat").string()) << " u 1:2:3:4 w p pt 7 ps 0.2 palette notitle\"\n"
    << "set title 'from the front'\nset view 62,32\neval plot_it\n"
    << "unset label 1\nset title 'from behind'\nset view 62,212\neval plot_it\n"
    << "unset multiplot\n";
  run_gnuplot("pngcairo size 1600,820 font 'sans,10'", s.str(), png, "deviation picture");
}

}  // namespace

nlohmann::json write_job_report(const std::filesystem::path& file, std::int64_t job, const sp::ModelSpec& spec,
                                const sp::TriangleMesh& reference, const std::string& reference_name,
                                const std::string& reference_kind, const CloudSummary& cloud, const ModelSummary& model,
                                const nlohmann::json& coverage) {
  const double tolerance = 3.0 * spec.precision_mm;
  std::vector<double> cloud_dev;
  const sp::DeviationStats cloud_stats = sp::signed_deviation(cloud.positions, reference, tolerance, &cloud_dev);
  const std::string date = utc_now();
  nlohmann::json r = {
      {"format", "scancell-inspection-report"},
      {"version", 1},
      {"job", job},
      {"date_utc", date},
      {"spec", {{"precision_mm", spec.precision_mm}, {"density_per_mm2", spec.density_per_mm2}}},
      {"reference", reference_name},
      {"reference_kind", reference_kind},
      {"sign", "+ outside the reference surface (along its outward normal), - inside"},
      {"tolerance_mm", tolerance},
      {"cloud", stats_json(cloud_stats)},
      {"model", stats_json(sp::signed_deviation(model.positions, reference, tolerance))},
      {"coverage", coverage}};
  // The picture beside the report; a failure to draw it is reported in it, not hidden, and keeps the figures.
  const auto png = file.parent_path() / "deviation.png";
  char title[768];
  std::snprintf(title, sizeof title,
                "job %lld: cloud of %zu samples against %s (%s), %s\nspec %g mm, %g samples/mm²: mean %+.4f mm, RMS %.4f mm, "
                "95 %% within %.4f mm, max %.4f mm, %.1f %% within ±%g mm",
                static_cast<long long>(job), cloud_stats.points, std::filesystem::path(reference_name).filename().c_str(),
                reference_kind.c_str(), date.c_str(), spec.precision_mm, spec.density_per_mm2, cloud_stats.mean_mm,
                cloud_stats.rms_mm, cloud_stats.p95_abs_mm, cloud_stats.max_abs_mm, 100.0 * cloud_stats.within_tolerance, tolerance);
  std::filesystem::create_directories(file.parent_path());
  try {
    write_deviation_png(cloud.positions, cloud_dev, tolerance, title, png);
    r["deviation_png"] = png.string();
  } catch (const std::exception& e) {
    r["deviation_png_error"] = e.what();
  }
  std::filesystem::create_directories(file.parent_path());
  write_file_durably(file, r.dump(2) + "\n");
  return r;
}

}  // namespace scancell::daemon
