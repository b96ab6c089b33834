// Plan-quality benchmark (thesis ch. 5 experiments and docs/quality.md): every synthetic object and every
// mesh in ../shared/meshes, a rough model at ρ_rel = −5 with σ_rm = 0.005·R_min, planned by 3M (greedy and
// constrained greedy t_r = 0.2) and by what an operator would run instead (fixed turntable programs, a
// set-covered view sphere), all verified by the same virtual scanner on the fine model.
//
//   bench_quality [--meshes DIR] [--only a,b] [--csv FILE] [--refine-mm E] [--rough-vertices N] [--rough-noise-mm S] [--seed N]
//                 [--threads N] [--quick]
// --refine-mm 0 keeps the shared meshes as they are (the QUALITY-TARGETS measure: analytic m_v over their own
// vertices); --rough-vertices N replaces ρ_rel = −5 by a fixed rough-model size (QUALITY-TARGETS used 1000).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "planner/sim/baselines.hpp"
#include "planner/config.hpp"
#include "planner/core/exact_cover.hpp"
#include "planner/plan.hpp"
#include "planner/sim/synthetic.hpp"
#include "planner/sim/verify.hpp"
#include "bench_common.hpp"
#include "bench_objects.hpp"

namespace sp = scancell::planner;
namespace bench = scancell::bench;
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

struct Object {
  std::string name;
  std::function<sp::TriangleMesh()> make;
};

struct Row {
  std::string object, family, method;
  std::size_t fine_vertices = 0, rough_vertices = 0;
  double r_f = 0.0;
  std::size_t views = 0;
  double estimated = std::nan(""), mv = 0.0, mv_analytic = 0.0, unmeasurable = std::nan("");
  double plan_s = 0.0, verify_s = 0.0;
  double bound = std::nan("");      // exact mode: proven lower bound on the view count
  std::string solver_status;
  std::vector<double> progression;  // verified cumulative m_v per view
};

std::string fmt(double v, const char* f = "%.4f") {
  if (!std::isfinite(v)) return "-";
  char b[32];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

/// Views needed to reach m_v >= target along a progression (0 when never).
std::size_t views_to_reach(const std::vector<double>& prog, double target) {
  for (std::size_t k = 0; k < prog.size(); ++k)
    if (prog[k] >= target - 1e-9) return k + 1;
  return 0;
}
double mv_at(const std::vector<double>& prog, std::size_t views) {
  if (prog.empty() || views == 0) return 0.0;
  return prog[std::min(views, prog.size()) - 1];
}

struct Options {
  std::string meshes_dir = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes";
  std::string csv_path = "quality.csv";
  std::set<std::string> only;
  double refine_mm = 2.0;
  std::uint64_t seed = 1;
  int threads = 0;
  bool quick = false;
  std::size_t rough_vertices = 0;  // 0: ρ_rel = −5
  double rough_noise_mm = -1.0;    // < 0: σ_rm = 0.005·R_min
  std::string settings_file;       // planner settings for 3M (cover mode and t_r are set per method)
};

/// The options, or nothing after printing the usage.
std::optional<Options> parse_options(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&] { return bench::option_value(argc, argv, i); };
    if (a == "--meshes") o.meshes_dir = value();
    else if (a == "--csv") o.csv_path = value();
    else if (a == "--refine-mm") o.refine_mm = std::stod(value());
    else if (a == "--seed") o.seed = std::stoull(value());
    else if (a == "--threads") o.threads = std::stoi(value());
    else if (a == "--quick") o.quick = true;
    else if (a == "--rough-vertices") o.rough_vertices = std::stoull(value());
    else if (a == "--rough-noise-mm") o.rough_noise_mm = std::stod(value());
    else if (a == "--settings") o.settings_file = value();
    else if (a == "--only") {
      std::stringstream ss(value());
      for (std::string t; std::getline(ss, t, ',');) o.only.insert(t);
    } else {
      std::cerr << "usage: bench_quality [--meshes DIR] [--only a,b] [--csv FILE] [--refine-mm E] [--rough-vertices N] [--rough-noise-mm S] [--settings FILE.yaml] [--seed N] [--threads N] [--quick]\n";
      return std::nullopt;
    }
  }
  return o;
}

/// The synthetic objects (sized to the sensor's footprint F_s), the CAD parts and the shared meshes.
std::vector<Object> make_objects(double fs_mm2, const Options& o) {
  std::vector<Object> objects;
  objects.push_back({"convex-patch-dw0.04", [fs_mm2] { return sp::convex_patch(std::sqrt(2.55 * fs_mm2), 0.04, 1.0); }});
  for (double dw : {0.1, 0.3, 0.5, 0.7, 1.0}) {
    char name[48];
    std::snprintf(name, sizeof name, "cavity-dw%.1f", dw);
    objects.push_back({name, [fs_mm2, dw] {
                         const double plate = std::sqrt(0.55 * fs_mm2);
                         return sp::cavity_patch(plate, 0.8 * plate, dw, 0.5);
                       }});
  }
  for (auto& b : bench::cad_objects(1.5, 0.0)) objects.push_back({b.name, std::move(b.make)});
  for (auto& b : bench::shared_mesh_objects(o.meshes_dir, o.refine_mm)) objects.push_back({b.name, std::move(b.make)});
  return objects;
}

/// One object's runs: what every method is judged on, and where its rows go.
struct Bench {
  const sp::TriangleMesh& fine;
  const sp::SensorModel& sensor;
  const sp::ModelSpec& spec;
  const Options& o;
  const sp::RoughModelOptions& rough;
  std::string name;
  double area = 0.0, fs_mm2 = 0.0;
  std::vector<Row>& rows;

  /// Verified by the virtual scanner on the fine model (same seed for every method).
  void verify(Row& r, const std::vector<sp::Viewpoint>& views, const std::vector<double>& est) const {
    std::vector<sp::ScanPose> poses;
    for (const auto& v : views) poses.push_back(sp::scan_pose(v));
    sp::VerifyOptions vo;
    vo.seed = o.seed;
    const auto t = Clock::now();
    const sp::Verification v = sp::verify_views(fine, sensor, spec, poses, est, vo);
    r.verify_s = scancell::seconds_since(t);
    r.views = views.size();
    r.mv = v.mv;
    r.mv_analytic = v.mv_analytic;
    for (const auto& w : v.views) r.progression.push_back(w.cumulative);
  }

  void emit(Row r) const {
    r.object = name;
    r.fine_vertices = fine.vertices.size();
    r.r_f = area / fs_mm2;
    char reach[48];
    auto v = [&](double t) { const auto n = views_to_reach(r.progression, t); return n ? std::to_string(n) : std::string("-"); };
    std::snprintf(reach, sizeof reach, "%s/%s/%s", v(0.95).c_str(), v(0.99).c_str(), v(0.999).c_str());
    std::printf("%-20s %-26s %6zu %6zu %9s %9.4f %9.4f %8s %14s %8.2f %8.2f\n", r.object.c_str(), r.method.c_str(), r.views,
                r.rough_vertices, fmt(r.estimated).c_str(), r.mv, r.mv_analytic, fmt(r.unmeasurable).c_str(), reach, r.plan_s,
                r.verify_s);
    std::fflush(stdout);
    rows.push_back(std::move(r));
  }

  /// 3M, plain and constrained greedy, and the exact program with the same registration constraint.
  void three_m() const {
    for (const auto mode : {sp::CoverMode::greedy, sp::CoverMode::constrained, sp::CoverMode::exact}) {
      sp::PlannerSettings settings = o.settings_file.empty() ? sp::PlannerSettings{} : sp::load_planner_settings(o.settings_file);
      settings.seed = o.seed;
      settings.cover.mode = mode;
      settings.cover.registration_threshold = 0.2;
      Row r;
      r.family = "3M";
      r.method = mode == sp::CoverMode::greedy ? "3M greedy" : mode == sp::CoverMode::constrained ? "3M constrained t_r=0.2" : "3M exact t_r=0.2";
      const auto t = Clock::now();
      const sp::ViewPlan plan = sp::plan_views(fine, sensor, spec, settings, rough);
      r.plan_s = scancell::seconds_since(t);
      r.rough_vertices = plan.rough.size();
      r.estimated = plan.cover.cumulative_fraction.empty() ? 0.0 : plan.cover.cumulative_fraction.back();
      r.unmeasurable = 1.0 - plan.cover.measurable_fraction;
      if (plan.exact_used) {
        r.bound = plan.exact.bound;
        r.solver_status = plan.exact.status;
      }
      verify(r, plan.views, plan.cover.cumulative_fraction);
      emit(std::move(r));
    }
  }

  /// Fixed turntable programs.
  void turntables() const {
    const std::vector<std::vector<double>> elevation_sets = {{30.0}, {-30.0, 30.0}, {-45.0, 0.0, 45.0}};
    const std::vector<int> steps = o.quick ? std::vector<int>{8, 24} : std::vector<int>{4, 6, 8, 12, 16, 24};
    for (const auto& set : elevation_sets)
      for (int k : steps) {
        std::vector<double> el;
        for (double d : set) el.push_back(d * std::numbers::pi / 180.0);
        Row r;
        r.family = "turntable";
        r.method = "turntable " + std::to_string(k) + "x" + std::to_string(set.size());
        verify(r, sp::turntable_program(fine, sensor, spec, k, el), {});
        emit(std::move(r));
      }
  }

  /// View spheres, set-covered by the same greedy on the same rough model and measurability test.
  void view_spheres() const {
    for (int sub : {2, 3}) {
      Row r;
      r.family = "view sphere";
      r.method = "view sphere s" + std::to_string(sub) + " x8 twists";
      const auto t = Clock::now();
      const sp::RoughModel rm = sp::build_rough_model(fine, rough);
      const sp::OcclusionScene scene(rm.mesh());
      const auto cands = sp::view_sphere_candidates(fine, sensor, spec, sub, 8);
      const auto m = sp::build_measurability(rm, scene, sensor, spec, cands);
      sp::CoverSettings cs;
      cs.mode = sp::CoverMode::greedy;
      const sp::CoverResult cover = sp::greedy_cover(m, rm.area_mm2, cs);
      r.plan_s = scancell::seconds_since(t);
      r.rough_vertices = rm.size();
      r.estimated = cover.cumulative_fraction.empty() ? 0.0 : cover.cumulative_fraction.back();
      r.unmeasurable = 1.0 - cover.measurable_fraction;
      std::vector<sp::Viewpoint> views;
      for (auto j : cover.views) views.push_back(cands[j]);
      verify(r, views, cover.cumulative_fraction);
      emit(std::move(r));
    }
  }
};

void write_csv(const std::vector<Row>& rows, const std::string& path) {
  std::ofstream csv(path);
  csv << "object,fine_vertices,r_f,method,views,rough_vertices,estimated_m,verified_m_v,analytic_m_v,"
         "unmeasurable_share,views_to_mv_0.95,views_to_mv_0.99,views_to_mv_0.999,plan_s,verify_s,exact_bound_views,"
         "exact_status\n";
  // The last two columns were in the header and missing from the rows until 2026-11-29.
  for (const auto& r : rows)
    csv << r.object << ',' << r.fine_vertices << ',' << fmt(r.r_f, "%.3f") << ',' << r.method << ',' << r.views << ','
        << r.rough_vertices << ',' << fmt(r.estimated) << ',' << fmt(r.mv) << ',' << fmt(r.mv_analytic) << ','
        << fmt(r.unmeasurable) << ',' << views_to_reach(r.progression, 0.95) << ',' << views_to_reach(r.progression, 0.99)
        << ',' << views_to_reach(r.progression, 0.999) << ',' << fmt(r.plan_s, "%.3f") << ',' << fmt(r.verify_s, "%.3f") << ','
        << fmt(r.bound, "%.2f") << ",\"" << r.solver_status << "\"\n";  // the status holds commas
}

/// Per object, in the order run: its rows.
std::vector<std::pair<std::string, std::vector<const Row*>>> by_object(const std::vector<Row>& rows) {
  std::vector<std::pair<std::string, std::vector<const Row*>>> out;
  for (const auto& r : rows) {
    if (out.empty() || out.back().first != r.object) out.push_back({r.object, {}});
    out.back().second.push_back(&r);
  }
  return out;
}

void print_comparison(const std::vector<Row>& rows) {
  std::printf("\nper object: best turntable program (highest m_v, then fewest views) vs 3M greedy and the view sphere\n");
  std::printf("%-20s %5s %-16s %5s %7s | %5s %7s %9s %11s | %-10s %5s %7s\n", "object", "r_f", "turntable best", "views",
              "m_v", "3M", "m_v", "3M_to_TT", "3M_m@TTviews", "sphere", "views", "m_v");
  for (const auto& [name, list] : by_object(rows)) {
    const Row *tt = nullptr, *g = nullptr, *sph = nullptr;
    for (const Row* r : list) {
      if (r->family == "turntable" && (!tt || r->mv > tt->mv + 1e-9 || (std::abs(r->mv - tt->mv) <= 1e-9 && r->views < tt->views))) tt = r;
      if (r->method == "3M greedy") g = r;
      if (r->family == "view sphere" && (!sph || r->mv > sph->mv)) sph = r;
    }
    if (!tt || !g || !sph) continue;
    const std::size_t reach = views_to_reach(g->progression, tt->mv);
    std::printf("%-20s %5.2f %-16s %5zu %7.4f | %5zu %7.4f %9s %11.4f | %-10s %5zu %7.4f\n", name.c_str(), g->r_f,
                tt->method.c_str(), tt->views, tt->mv, g->views, g->mv, reach ? std::to_string(reach).c_str() : "never",
                mv_at(g->progression, tt->views), sph->method.substr(12, 2).c_str(), sph->views, sph->mv);
  }
}

void print_efficiency(const std::vector<Row>& rows) {
  std::printf("\nset cover efficiency e_v = n_best / n (thesis 1.3), registration t_r = 0.2, exact mode %.0f s limit\n",
              sp::CoverSettings{}.exact_time_limit_s);
  std::printf("%-20s %10s %7s %7s %9s %9s %9s  %s\n", "object", "constrained", "exact", "bound", "ev_bound", "ev_exact",
              "m_v_exact", "solver");
  for (const auto& [name, list] : by_object(rows)) {
    const Row *c = nullptr, *x = nullptr;
    for (const Row* r : list) {
      if (r->method == "3M constrained t_r=0.2") c = r;
      if (r->method == "3M exact t_r=0.2") x = r;
    }
    if (!c || !x || c->views == 0) continue;
    const double lb = std::ceil(x->bound - 1e-6);
    std::printf("%-20s %10zu %7zu %7.0f %9.3f %9.3f %9.4f  %s\n", name.c_str(), c->views, x->views, lb,
                lb / static_cast<double>(c->views), static_cast<double>(x->views) / static_cast<double>(c->views), x->mv,
                x->solver_status.c_str());
  }
}

}  // namespace

static int run_bench(int argc, char** argv) {
  const std::optional<Options> parsed = parse_options(argc, argv);
  if (!parsed) return 2;
  Options o = *parsed;
  const sp::SensorModel sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const sp::ModelSpec spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  const double fs_mm2 = sp::sensor_footprint_mm2(sensor, spec);
  if (o.rough_noise_mm < 0.0) o.rough_noise_mm = 0.005 * sensor.range_min_mm;
  const std::vector<Object> objects = make_objects(fs_mm2, o);

  const int n_threads = o.threads > 0 ? o.threads : tbb::info::default_concurrency();
  tbb::task_arena arena(n_threads);
  std::vector<Row> rows;
  std::printf("sensor %s, spec %.3f mm / %.1f samples/mm2, F_s %.0f mm2, rough %s, sigma_rm %.3f mm, shared meshes "
              "refined to %.1f mm edges, seed %llu, %d threads\n",
              sensor.name.c_str(), spec.precision_mm, spec.density_per_mm2, fs_mm2,
              o.rough_vertices ? (std::to_string(o.rough_vertices) + " vertices").c_str() : "rho_rel -5", o.rough_noise_mm,
              o.refine_mm, static_cast<unsigned long long>(o.seed), n_threads);
  std::printf("%-20s %-26s %6s %6s %9s %9s %9s %8s %14s %8s %8s\n", "object", "method", "views", "rows", "est_m", "m_v",
              "m_v_anal", "unmeas", "views_95/99/99.9", "plan_s", "verif_s");
  arena.execute([&] {
    for (const auto& obj : objects) {
      if (!o.only.empty() && !o.only.count(obj.name)) continue;
      const sp::TriangleMesh fine = obj.make();
      sp::RoughModelOptions rough;
      if (o.rough_vertices) rough.target_vertices = o.rough_vertices;
      else rough.rho_rel = -5.0;
      rough.normal_noise_mm = o.rough_noise_mm;
      rough.seed = o.seed;
      Bench b{fine, sensor, spec, o, rough, obj.name, 0.0, fs_mm2, rows};
      for (const auto& t : fine.triangles) b.area += sp::triangle_area(fine, t);
      b.three_m();
      b.turntables();
      b.view_spheres();
    }
  });
  write_csv(rows, o.csv_path);
  print_comparison(rows);
  print_efficiency(rows);
  std::printf("\n3M_to_TT: 3M greedy views to reach the best turntable program's m_v; 3M_m@TTviews: 3M's m_v after as many "
              "views as that program has (all of them if fewer). CSV: %s\n", o.csv_path.c_str());
  return 0;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_quality", [&] { return run_bench(argc, argv); });
}
