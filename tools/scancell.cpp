// scancell: command-line front end of the planner.
//   scancell plan --mesh M --sensor S --spec P [--settings X] --out plan.json [options]
#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "calibration/results.hpp"
#include "common/errors.hpp"
#include "planner/plan.hpp"
#include "planner/placement.hpp"
#include "planner/plan_file.hpp"
#include "planner/reconstruction/product.hpp"
#include "planner/sim/verify.hpp"
#include "tools/plan_picture.hpp"

namespace sp = scancell::planner;

namespace {

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

const char* kPlanUsage =
    "usage: scancell plan --mesh FILE --sensor SENSOR.yaml --spec SPEC.yaml --out PLAN.json [options]\n"
    "  --settings FILE.yaml      planner settings (viewpoints, cover, matrix); defaults if omitted\n"
    "  --scale K                 multiply mesh coordinates by K to get mm\n"
    "  --fit-mm L                scale so the longest bounding-box side is L mm\n"
    "  --rough-vertices N        quadric-decimate the rough model to N vertices\n"
    "  --rho-rel R               decimate to 2^R times the input vertex count (R <= 0, thesis 5.3)\n"
    "  --rough-noise-mm SIGMA    Gaussian displacement along the normal (thesis 5.4)\n"
    "  --seed N                  seed for the noise (default: settings seed)\n"
    "  --segments FILE           surface patch label per mesh vertex (integers, -1 none), in vertex order\n"
    "                            after welding; adds single-best-view candidates per patch (thesis 6.3.4)\n"
    "  --cover greedy|constrained|exact   override the settings' cover mode (exact: CBC integer program,\n"
    "                            registration enforced when t_r > 0, greedy warm start, cover.exact_time_limit_s);\n"
    "                            with --cell and without --cover, constrained reads as greedy, as in a job\n"
    "  --threads N               worker threads (default all cores; the plan does not depend on it)\n"
    "  --cell CELL.yaml          plan for this cell (config/cells): reachable, collision-free views with their\n"
    "                            axis targets, in the order of least travel\n"
    "  --calibration F[,F]       apply calibration result files (docs/calibration.md) to the sensor and cell\n"
    "  --placement auto|as-given with --cell: auto plans the object's most probable stable resting poses on the\n"
    "                            plate and keeps the one measuring the most area with the fewest views\n"
    "                            (settings placement.*); as-given (default) keeps the mesh's +z up\n"
    "  --png FILE.png            the plan as a picture: rows predicted measured or left, each view's camera\n"
    "                            numbered in execution order, boresight and scan path (needs gnuplot)\n"
    "  --quiet                   no summary table\n";

const char* kVerifyUsage =
    "usage: scancell verify --plan PLAN.json [--fine MESH] [options]\n"
    "  executes the plan with the virtual scanner on the fine model and reports verified measurability m_v\n"
    "  --fine FILE                fine model (default: the plan's object.mesh)\n"
    "  --scale K | --fit-mm L     place the fine model with this scale instead of the plan's object transform\n"
    "  --seed N                   noise / pose-error seed (default 1)\n"
    "  --no-noise                 noise-free range images\n"
    "  --sigma-p-mm S             positioner position error σ_p (mm, thesis 7.2.4)\n"
    "  --sigma-a-rad S            boresight axis error σ_a (rad)\n"
    "  --sigma-t-rad S            twist error σ_t (rad)\n"
    "  --pose-error N             Monte Carlo: execute the plan N times with sampled pose errors, report\n"
    "                             mean ± sd of m_v (the noise stream is the same in every trial)\n"
    "  --no-analytic              skip the analytic m_v on the fine mesh\n"
    "  --refine-mm E              split fine-mesh edges longer than E mm first (surface unchanged; evens out\n"
    "                             the vertex sampling m_v is weighted over on coarse CAD meshes)\n"
    "  --report FILE.json         per-view and total figures as JSON\n"
    "  --coverage-ply FILE.ply    fine mesh coloured measured (grey) / not (red)\n"
    "  --png FILE.png             measurability projection from +X -X +Y -Y +Z -Z, labelled, with a legend and\n"
    "                             the headline figures (gnuplot; without it the bare views, a message, exit 1)\n"
    "  --threads N                worker threads (default all cores)\n"
    "  --quiet                    no table\n"
    "usage: scancell scan --plan PLAN.json --view K --out IMAGE.ply [--fine MESH] [--scale K | --fit-mm L] "
    "[--seed N] [--no-noise]\n"
    "  one view of the plan through the virtual scanner, saved as a range image (docs/range-image-format.md)\n"
    "usage: scancell pose-error --sensor SENSOR.yaml [--cell CELL.yaml] [--sigma-p-mm S] [--sigma-a-rad S]\n"
    "       [--sigma-t-rad S] [--fd F]\n"
    "  expected relative precision, density, footprint and depth-of-field erosion, suggested f_d, countermeasures\n"
    "usage: scancell fuse --scans PATH[,PATH...] --spec SPEC.yaml --out MODEL.ply [--cloud CLOUD.ply]\n"
    "       [--cloud-spacing-mm S]\n"
    "  the job's product offline: range images (files, or every .ply in a directory, in name order) fused into\n"
    "  the surface model (open where nothing was measured); --cloud also writes the spec-compliant samples\n"
    "  (--cloud-spacing-mm: one per cube of that side; the model uses all of them)\n";

/// Simple --key value parser that refuses unknown or repeated options.
std::map<std::string, std::string> parse(int argc, char** argv, const std::vector<std::string>& with_value,
                                         const std::vector<std::string>& flags) {
  std::map<std::string, std::string> out;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    auto is = [&](const std::vector<std::string>& v) { return std::find(v.begin(), v.end(), a) != v.end(); };
    if (out.count(a)) throw UsageError("option " + a + " given twice");
    if (is(flags)) {
      out[a] = "1";
    } else if (is(with_value)) {
      if (i + 1 >= argc) throw UsageError("option " + a + " needs a value");
      out[a] = argv[++i];
    } else {
      throw UsageError("unknown option '" + a + "'");
    }
  }
  return out;
}

double number(const std::map<std::string, std::string>& o, const std::string& key) {
  const std::string& s = o.at(key);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || !std::isfinite(v)) throw UsageError(key + ": '" + s + "' is not a finite number");
  return v;
}

std::uint64_t whole(const std::map<std::string, std::string>& o, const std::string& key) {
  const std::string& s = o.at(key);
  std::uint64_t v = 0;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size()) throw UsageError(key + ": '" + s + "' is not a whole number >= 0");
  return v;
}

/// Writes bytes to a temporary file and renames, so a reader never sees half a file.
void write_bytes(const std::string& out, const std::string& bytes) {
  const std::string tmp = out + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw std::runtime_error(out + ": cannot open for writing");
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!f.flush()) throw std::runtime_error(out + ": write failed");
  }
  if (std::rename(tmp.c_str(), out.c_str()) != 0) throw std::runtime_error(out + ": cannot rename " + tmp + ": " + std::strerror(errno));
}

void write_json(const std::string& out, const nlohmann::json& j) { write_bytes(out, j.dump(2) + "\n"); }

int cmd_plan(int argc, char** argv) {
  const auto o = parse(argc, argv,
                       {"--mesh", "--sensor", "--spec", "--settings", "--out", "--scale", "--fit-mm", "--rough-vertices",
                        "--rho-rel", "--rough-noise-mm", "--seed", "--cover", "--threads", "--segments", "--cell",
                        "--calibration", "--placement", "--png"},
                       {"--quiet"});
  for (const char* k : {"--mesh", "--sensor", "--spec", "--out"})
    if (!o.count(k)) throw UsageError(std::string("missing ") + k);
  if (o.count("--scale") && o.count("--fit-mm")) throw UsageError("give --scale or --fit-mm, not both");

  sp::SensorModel sensor = sp::load_sensor(o.at("--sensor"));
  const sp::ModelSpec spec = sp::load_spec(o.at("--spec"));
  sp::PlannerSettings settings = o.count("--settings") ? sp::load_planner_settings(o.at("--settings")) : sp::PlannerSettings{};
  if (o.count("--cover")) {
    const std::string& m = o.at("--cover");
    if (m == "greedy") settings.cover.mode = sp::CoverMode::greedy;
    else if (m == "constrained") settings.cover.mode = sp::CoverMode::constrained;
    else if (m == "exact") settings.cover.mode = sp::CoverMode::exact;
    else throw UsageError("--cover: '" + m + "' is not greedy, constrained or exact");
  } else if (o.count("--cell") && settings.cover.mode != sp::registered_to_model(settings.cover).mode) {
    // On a cell the plan previews a job, whose every view registers to the object's model through the axes:
    // it covers as the daemon does (docs/daemon.md). --cover constrained keeps thesis 4.4.3's constraint.
    settings.cover = sp::registered_to_model(settings.cover);
    if (!o.count("--quiet"))
      std::cerr << "scancell: on a cell the cover is greedy, as a job's (every view registers to the model); "
                   "--cover constrained keeps the between-view registration constraint\n";
  }
  if (o.count("--placement")) {
    const std::string& m = o.at("--placement");
    if (m == "auto") settings.placement.automatic = true;
    else if (m == "as-given") settings.placement.automatic = false;
    else throw UsageError("--placement: '" + m + "' is not auto or as-given");
  }
  if (settings.placement.automatic && !o.count("--cell"))
    throw UsageError("placement auto chooses how the object rests on a turntable: it needs --cell");
  sp::RoughModelOptions rough;
  if (o.count("--rough-vertices")) {
    const std::uint64_t n = whole(o, "--rough-vertices");
    if (n < sp::kMinRoughVertices || n > sp::kMaxRoughVertices)
      throw UsageError("--rough-vertices: must be in [" + std::to_string(sp::kMinRoughVertices) + ", " +
                       std::to_string(sp::kMaxRoughVertices) + "], got " + std::to_string(n));
    rough.target_vertices = n;
  }
  if (o.count("--rho-rel")) rough.rho_rel = number(o, "--rho-rel");
  if (o.count("--rough-noise-mm")) rough.normal_noise_mm = number(o, "--rough-noise-mm");
  if (o.count("--seed")) settings.seed = whole(o, "--seed");
  rough.seed = settings.seed;
  const int threads = o.count("--threads") ? static_cast<int>(whole(o, "--threads")) : 0;

  sp::ObjectSource source;
  source.mesh_path = o.at("--mesh");
  sp::TriangleMesh mesh = sp::load_mesh(source.mesh_path, &source.load);
  if (source.load.degenerate_dropped)
    std::cerr << "scancell: " << source.mesh_path << ": dropped " << source.load.degenerate_dropped << " degenerate triangles\n";
  if (o.count("--scale")) {
    source.scale = number(o, "--scale");
    if (!(source.scale > 0.0)) throw UsageError("--scale must be > 0");
  } else if (o.count("--fit-mm")) {
    const double l = number(o, "--fit-mm");
    if (!(l > 0.0)) throw UsageError("--fit-mm must be > 0");
    source.scale = sp::fit_scale(mesh, l);
  }
  sp::apply_scale(mesh, source.scale);
  if (o.count("--segments")) {
    const std::string& f = o.at("--segments");
    std::ifstream in(f);
    if (!in) throw UsageError("--segments: cannot open " + f);
    std::string tok;
    for (std::size_t k = 0; in >> tok; ++k) {
      int v = 0;
      auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
      if (ec != std::errc() || p != tok.data() + tok.size() || v < -1)
        throw UsageError(f + ": label " + std::to_string(k) + " '" + tok + "' is not an integer >= -1");
      rough.vertex_labels.push_back(v);
    }
    if (rough.vertex_labels.size() != mesh.vertices.size())
      throw UsageError(f + ": " + std::to_string(rough.vertex_labels.size()) + " labels for " +
                       std::to_string(mesh.vertices.size()) + " mesh vertices");
  }

  std::optional<sp::CellModel> cell;
  if (o.count("--cell")) cell = sp::load_cell(o.at("--cell"));
  if (o.count("--calibration")) {
    // Comma-separated result files of calibration runs (docs/calibration.md), applied in order.
    std::stringstream list(o.at("--calibration"));
    for (std::string f; std::getline(list, f, ',');) {
      const auto rec = scancell::calibration::load_calibration(f);
      sp::CellModel scratch;
      scratch.name = rec.cell;
      if (!cell && rec.kind != "sensor") throw UsageError(f + ": a " + rec.kind + " calibration needs --cell");
      for (const auto& change : scancell::calibration::apply_calibration(rec, sensor, cell ? *cell : scratch))
        if (!o.count("--quiet")) std::cerr << "scancell: calibration " << f << ": " << change << "\n";
    }
  }
  sp::ViewPlan plan = settings.placement.automatic
                          ? sp::plan_with_placement(mesh, sensor, spec, settings, rough, threads, *cell)
                          : sp::plan_views(std::move(mesh), sensor, spec, settings, rough, threads, cell ? &*cell : nullptr);
  plan.object = source;
  if (plan.rough_report.faces_rejected_by_decimator)
    std::cerr << "scancell: decimator rejected " << plan.rough_report.faces_rejected_by_decimator << " non-manifold faces\n";

  write_json(o.at("--out"), sp::plan_to_json(plan));
  if (o.count("--png")) scancell::tools::write_plan_png(plan, std::filesystem::path(source.mesh_path).filename().string(), o.at("--png"));
  if (!o.count("--quiet")) std::cout << sp::plan_summary(plan);
  return 0;
}

/// The fine model placed in the plan's object frame: the plan's recorded transform, or --scale / --fit-mm.
sp::TriangleMesh place_fine(const sp::PlanFile& plan, const std::map<std::string, std::string>& o) {
  const std::string path = o.count("--fine") ? o.at("--fine") : plan.mesh_path;
  if (o.count("--scale") && o.count("--fit-mm")) throw UsageError("give --scale or --fit-mm, not both");
  sp::TriangleMesh mesh = sp::load_mesh(path);
  if (o.count("--scale") || o.count("--fit-mm")) {
    const double k = o.count("--scale") ? number(o, "--scale") : sp::fit_scale(mesh, number(o, "--fit-mm"));
    if (!(k > 0.0)) throw UsageError("--scale / --fit-mm must be > 0");
    sp::apply_scale(mesh, k);
  } else {
    for (auto& v : mesh.vertices) v = (plan.object_transform * v.homogeneous()).head<3>();
  }
  return mesh;
}

int cmd_verify(int argc, char** argv) {
  const auto o = parse(argc, argv,
                       {"--plan", "--fine", "--scale", "--fit-mm", "--seed", "--sigma-p-mm", "--sigma-a-rad", "--sigma-t-rad",
                        "--pose-error",
                        "--report", "--coverage-ply", "--png", "--threads", "--refine-mm"},
                       {"--no-noise", "--no-analytic", "--quiet"});
  if (!o.count("--plan")) throw UsageError("missing --plan");
  const sp::PlanFile plan = sp::load_plan_file(o.at("--plan"));
  sp::TriangleMesh fine = place_fine(plan, o);
  if (o.count("--refine-mm")) {
    const double e = number(o, "--refine-mm");
    if (!(e > 0.0)) throw UsageError("--refine-mm must be > 0");
    fine = sp::refine_edges(fine, e);
  }
  sp::VerifyOptions opt;
  if (o.count("--seed")) opt.seed = whole(o, "--seed");
  opt.noise = !o.count("--no-noise");
  opt.analytic = !o.count("--no-analytic");
  if (o.count("--sigma-p-mm")) opt.pose_error.sigma_p_mm = number(o, "--sigma-p-mm");
  if (o.count("--sigma-a-rad")) opt.pose_error.sigma_a_rad = number(o, "--sigma-a-rad");
  if (o.count("--sigma-t-rad")) opt.pose_error.sigma_t_rad = number(o, "--sigma-t-rad");
  if (opt.pose_error.sigma_p_mm < 0.0 || opt.pose_error.sigma_a_rad < 0.0 || opt.pose_error.sigma_t_rad < 0.0)
    throw UsageError("pose error sigmas must be >= 0");
  opt.pose_seed = opt.seed;
  opt.occluders = plan.fixtures_in_object_frame();  // a plan made for a cell is verified with its plate
  const int trials = o.count("--pose-error") ? static_cast<int>(whole(o, "--pose-error")) : 0;
  if (o.count("--pose-error") && (trials < 1 || trials > 100000)) throw UsageError("--pose-error: trials must be in [1, 100000]");
  const int threads = o.count("--threads") ? static_cast<int>(whole(o, "--threads")) : 0;
  tbb::task_arena arena(threads > 0 ? threads : tbb::info::default_concurrency());
  sp::Verification v;
  sp::MonteCarloResult mc;
  arena.execute([&] {
    v = sp::verify_views(fine, plan.sensor, plan.spec, plan.views, plan.estimated_cumulative, opt);
    if (trials > 0) mc = sp::verify_monte_carlo(fine, plan.sensor, plan.spec, plan.views, opt, trials);
  });
  if (o.count("--report")) {
    nlohmann::json views = nlohmann::json::array();
    for (std::size_t k = 0; k < v.views.size(); ++k) {
      const auto& w = v.views[k];
      views.push_back({{"index", k},
                       {"samples", w.scan.samples},
                       {"compliant_samples", w.compliant_samples},
                       {"rays", w.scan.rays},
                       {"missed", w.scan.missed},
                       {"too_close", w.scan.too_close},
                       {"back_facing", w.scan.back_facing},
                       {"beyond_grazing", w.scan.beyond_grazing},
                       {"receiver_occluded", w.scan.receiver_occluded},
                       {"alone_area_mm2", w.alone_mm2},
                       {"gain_area_mm2", w.gain_mm2},
                       {"unique_area_mm2", w.unique_mm2},
                       {"cumulative_verified_measurability", w.cumulative},
                       {"cumulative_analytic_measurability", w.cumulative_analytic},
                       {"cumulative_estimated_measurability", std::isfinite(w.cumulative_estimated) ? nlohmann::json(w.cumulative_estimated) : nlohmann::json()}});
    }
    nlohmann::json r = {{"format", "scancell-verification"},
                        {"version", 1},
                        {"plan", plan.path},
                        {"fine_vertices", fine.vertices.size()},
                        {"fine_area_mm2", v.area_mm2},
                        {"seed", opt.seed},
                        {"noise", opt.noise},
                        {"pose_error",
                         {{"sigma_p_mm", opt.pose_error.sigma_p_mm},
                          {"sigma_a_rad", opt.pose_error.sigma_a_rad},
                          {"sigma_t_rad", opt.pose_error.sigma_t_rad}}},
                        {"verified_measurability", v.mv},
                        {"analytic_measurability", opt.analytic ? nlohmann::json(v.mv_analytic) : nlohmann::json()},
                        {"estimated_measurability", std::isfinite(v.estimated) ? nlohmann::json(v.estimated) : nlohmann::json()},
                        {"views", views},
                        {"seconds", v.seconds}};
    if (trials > 0)
      r["monte_carlo"] = {{"trials", trials}, {"mean", mc.mean}, {"sd", mc.sd}, {"min", mc.min}, {"max", mc.max},
                          {"per_trial", mc.mv}, {"seconds", mc.seconds}};
    write_json(o.at("--report"), r);
  }
  if (o.count("--coverage-ply")) sp::write_coverage_ply(fine, v.measured, o.at("--coverage-ply"));
  int status = 0;
  if (o.count("--png")) {
    char title[640];
    std::snprintf(title, sizeof title,
                  "%s: %zu views of %s\nverified m_v %.4f of %.0f mm² (virtual scanner%s), spec %g mm, %g samples/mm²",
                  std::filesystem::path(o.count("--fine") ? o.at("--fine") : plan.mesh_path).filename().c_str(),
                  plan.views.size(), std::filesystem::path(o.at("--plan")).filename().c_str(), v.mv, v.area_mm2,
                  opt.occluders.triangles.empty() ? "" : ", the cell's plate in the scene", plan.spec.precision_mm,
                  plan.spec.density_per_mm2);
    if (const std::string why = sp::write_coverage_picture(fine, v.measured, title, o.at("--png")); !why.empty()) {
      std::cerr << "scancell verify: " << o.at("--png") << ": " << why << "\n";
      status = 1;  // the figures stand; the picture is not the one asked for
    }
  }
  if (!o.count("--quiet")) std::cout << sp::verification_summary(v);
  if (trials > 0)
    std::cout << "Monte Carlo over pose error (" << trials << " trials, σ_p " << opt.pose_error.sigma_p_mm << " mm, σ_a "
              << opt.pose_error.sigma_a_rad << " rad, σ_t " << opt.pose_error.sigma_t_rad << " rad): m_v mean " << mc.mean
              << " sd " << mc.sd << " min " << mc.min << " max " << mc.max << " (" << mc.seconds << " s)\n";
  return status;
}

int cmd_scan(int argc, char** argv) {
  const auto o = parse(argc, argv, {"--plan", "--view", "--out", "--fine", "--scale", "--fit-mm", "--seed"}, {"--no-noise"});
  for (const char* k : {"--plan", "--view", "--out"})
    if (!o.count(k)) throw UsageError(std::string("missing ") + k);
  const sp::PlanFile plan = sp::load_plan_file(o.at("--plan"));
  const std::uint64_t k = whole(o, "--view");
  if (k >= plan.views.size())
    throw UsageError("--view " + std::to_string(k) + ": the plan has " + std::to_string(plan.views.size()) + " views");
  const sp::TriangleMesh fine = place_fine(plan, o);
  sp::TriangleMesh with_plate = fine;
  const sp::TriangleMesh plate = plan.fixtures_in_object_frame();
  sp::append_mesh(with_plate, plate);
  const sp::OcclusionScene scene(with_plate);
  sp::ScanOptions so;
  so.object_triangles = plate.triangles.empty() ? 0 : fine.triangles.size();
  so.seed = sp::mix_seed(o.count("--seed") ? whole(o, "--seed") : 1, k, 0);
  so.noise = !o.count("--no-noise");
  sp::ScanStats st;
  const sp::RangeImage img = sp::virtual_scan(scene, plan.sensor, plan.views[k], so, &st);
  sp::save_range_image(img, o.at("--out"));
  std::cout << "view " << k << ": " << st.samples << " samples of " << st.rays << " rays (missed " << st.missed
            << ", too close " << st.too_close << ", back-facing " << st.back_facing << ", beyond grazing "
            << st.beyond_grazing << ", receiver occluded " << st.receiver_occluded << ")\n";
  return 0;
}

/// The range-image files `--scans` names: files as given, directories' .ply files in name order.
std::vector<std::filesystem::path> scan_files(const std::string& list) {
  std::vector<std::filesystem::path> out;
  std::stringstream ss(list);
  for (std::string item; std::getline(ss, item, ',');) {
    if (item.empty()) throw UsageError("--scans: an empty path in '" + list + "'");
    const std::filesystem::path p(item);
    if (std::filesystem::is_directory(p)) {
      std::vector<std::filesystem::path> in;
      for (const auto& e : std::filesystem::directory_iterator(p))
        if (e.is_regular_file() && e.path().extension() == ".ply") in.push_back(e.path());
      if (in.empty()) throw UsageError("--scans: no .ply range images in " + item);
      std::sort(in.begin(), in.end());
      out.insert(out.end(), in.begin(), in.end());
    } else {
      out.push_back(p);
    }
  }
  return out;
}

int cmd_fuse(int argc, char** argv) {
  const auto o = parse(argc, argv, {"--scans", "--spec", "--out", "--cloud", "--cloud-spacing-mm"}, {});
  for (const char* k : {"--scans", "--spec", "--out"})
    if (!o.count(k)) throw UsageError(std::string("missing ") + k);
  const sp::ModelSpec spec = sp::load_spec(o.at("--spec"));
  std::vector<sp::ProductView> views;
  std::string job_file;  // the first image that names its job
  std::int64_t job = 0;
  for (const auto& f : scan_files(o.at("--scans"))) {
    sp::ProductView v;
    v.image = sp::load_range_image(f);  // a damaged file: DataError naming it
    if (v.image.valid_count() == 0) throw scancell::DataError(f.string() + ": no samples (an empty range image; leave it out)");
    // One job's images make one product: another job's view was registered to another placement.
    if (v.image.job > 0 && job > 0 && v.image.job != job)
      throw scancell::DataError(f.string() + ": from job " + std::to_string(v.image.job) + ", but " + job_file + " is from job " +
                                std::to_string(job) + " (a product is made from one job's range images)");
    if (v.image.job > 0 && job == 0) {
      job = v.image.job;
      job_file = f.string();
    }
    v.view = static_cast<int>(views.size());
    views.push_back(std::move(v));
  }
  sp::CloudSummary cloud;
  const double spacing = o.count("--cloud-spacing-mm") ? number(o, "--cloud-spacing-mm") : 0.0;
  if (!(spacing >= 0.0 && spacing <= 10.0)) throw UsageError("--cloud-spacing-mm must be in [0, 10] mm (0 keeps every sample)");
  const std::string cloud_bytes = sp::cloud_ply(views, 0, spec, cloud, true, spacing);
  sp::ModelSummary model;
  const sp::SurfaceMesh m = sp::fuse_model(cloud, spec, model);
  write_bytes(o.at("--out"), sp::surface_ply(m));
  if (o.count("--cloud")) write_bytes(o.at("--cloud"), cloud_bytes);
  std::cout << views.size() << " range images, " << cloud.compliant << " spec-compliant samples ("
            << cloud.points << " in the cloud) -> " << o.at("--out") << ": "
            << model.vertices << " vertices, " << model.triangles << " triangles, " << model.boundary_edges
            << " open edges (unmeasured holes left open), voxel " << model.voxel_mm << " mm\n";
  return 0;
}

int cmd_pose_error(int argc, char** argv) {
  const auto o = parse(argc, argv, {"--sensor", "--cell", "--fd", "--sigma-p-mm", "--sigma-a-rad", "--sigma-t-rad"}, {});
  if (!o.count("--sensor")) throw UsageError("missing --sensor");
  const sp::SensorModel sensor = sp::load_sensor(o.at("--sensor"));
  sp::PoseErrorModel e;
  if (o.count("--cell")) e = sp::load_cell(o.at("--cell")).pose_error;
  if (o.count("--sigma-p-mm")) e.sigma_p_mm = number(o, "--sigma-p-mm");
  if (o.count("--sigma-a-rad")) e.sigma_a_rad = number(o, "--sigma-a-rad");
  if (o.count("--sigma-t-rad")) e.sigma_t_rad = number(o, "--sigma-t-rad");
  if (e.sigma_p_mm < 0 || e.sigma_a_rad < 0 || e.sigma_t_rad < 0) throw UsageError("pose error sigmas must be >= 0");
  const double fd = o.count("--fd") ? number(o, "--fd") : 1.02;
  if (!(fd >= 1.0 && fd <= 2.0)) throw UsageError("--fd must be in [1, 2]");
  std::cout << sp::pose_error_report(sensor, e, fd);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::cerr << "usage: scancell COMMAND [options]\ncommands:\n"
                 "  plan    plan the views that measure an object to a specification\n"
                 "  verify  execute a plan with the virtual scanner on the fine model: verified measurability\n"
                 "  scan    one view of a plan through the virtual scanner, saved as a range image\n"
                 "  pose-error  the thesis' single-view pose-error effects (tables 7.3-7.5) for a sensor and cell\n"
                 "  fuse    range images fused into the object's surface model (the job's product, offline)\n\n"
              << kPlanUsage << kVerifyUsage;
    return argc < 2 ? 2 : 0;
  }
  const std::string cmd = argv[1];
  const char* usage = cmd == "plan" ? kPlanUsage : kVerifyUsage;
  try {
    if (argc == 3 && (!std::strcmp(argv[2], "--help") || !std::strcmp(argv[2], "-h"))) {
      std::cout << usage;
      return 0;
    }
    if (cmd == "plan") return cmd_plan(argc - 2, argv + 2);
    if (cmd == "verify") return cmd_verify(argc - 2, argv + 2);
    if (cmd == "scan") return cmd_scan(argc - 2, argv + 2);
    if (cmd == "pose-error") return cmd_pose_error(argc - 2, argv + 2);
    if (cmd == "fuse") return cmd_fuse(argc - 2, argv + 2);
    std::cerr << "scancell: unknown command '" << cmd << "'\n";
    return 2;
  } catch (const UsageError& e) {
    std::cerr << "scancell " << cmd << ": " << e.what() << "\n" << usage;
    return 2;
  } catch (const scancell::MeshError& e) {
    std::cerr << "scancell: mesh error: " << e.what() << "\n";
    return 3;
  } catch (const scancell::ConfigError& e) {
    std::cerr << "scancell: config error: " << e.what() << "\n";
    return 4;
  } catch (const scancell::DataError& e) {
    std::cerr << "scancell: data error: " << e.what() << "\n";
    return 5;
  } catch (const std::exception& e) {
    std::cerr << "scancell: error: " << e.what() << "\n";
    return 1;
  }
}
