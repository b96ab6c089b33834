// Set-cover benchmark: greedy vs the exact CBC program (issue 4) on the thesis-size instances (≈ 400 × 400 at
// densities 0.24 and 0.64, random and spatially correlated), and on a whole-object matrix. Prints, per
// instance, greedy's views (before/after redundancy elimination), the exact cover, the proven bound, the gap,
// the solver status and time, and e_v = n_best / n (thesis 1.3) of greedy against the proven bound.
//   bench_cover [--time-limit S] [--mesh FILE] [--skip-object] [--all-objects] [--no-exact]
// --all-objects: every mesh beside --mesh (shared/meshes) as a whole object; --no-exact: greedy and the local
// search only (each instance also reports the local search from constrained greedy's cover).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>

#include "planner/config.hpp"
#include "planner/core/exact_cover.hpp"
#include "planner/core/local_cover.hpp"
#include "planner/plan.hpp"
#include "planner/sim/synthetic.hpp"
#include "bench/bench_common.hpp"

namespace sp = scancell::planner;
using Clock = std::chrono::steady_clock;

namespace {

sp::MeasurabilityMatrix random_matrix(std::uint32_t rows, std::uint32_t cols, double density, unsigned seed) {
  std::mt19937 rng(seed);
  std::bernoulli_distribution coin(density);
  sp::MeasurabilityMatrix m;
  m.n_rows = rows;
  for (std::uint32_t j = 0; j < cols; ++j) {
    std::vector<std::uint32_t> c;
    for (std::uint32_t r = 0; r < rows; ++r)
      if (coin(rng)) c.push_back(r);
    m.columns.emplace_back(c, rows);
  }
  return m;
}

/// A patch's matrix as the thesis built it: one viewpoint per rough vertex (VARIABLE, no twists or tilts).
struct PatchInstance {
  sp::MeasurabilityMatrix m;
  std::vector<double> w;
};
PatchInstance patch_matrix(const sp::TriangleMesh& fine, std::size_t rough_vertices) {
  const sp::SensorModel s = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const sp::ModelSpec spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  sp::RoughModelOptions ro;
  ro.target_vertices = rough_vertices;
  const sp::RoughModel rm = sp::build_rough_model(fine, ro);
  const sp::OcclusionScene scene(rm.mesh());
  sp::ViewpointSettings vs;
  vs.scheme = sp::ViewpointScheme::variable;
  vs.bisector_tilt = false;
  vs.open_direction_views = false;
  const auto cands = sp::generate_viewpoints(rm, scene, s, spec, vs);
  return {sp::build_measurability(rm, scene, s, spec, cands), rm.area_mm2};
}

bool g_exact = true;

void run(const char* name, const sp::MeasurabilityMatrix& m, const std::vector<double>& w, double t_r, double limit) {
  sp::CoverSettings g;
  g.mode = t_r > 0.0 ? sp::CoverMode::constrained : sp::CoverMode::greedy;
  g.registration_threshold = t_r;
  g.eliminate_redundant = false;
  const auto t0 = Clock::now();
  const std::size_t n_greedy = sp::greedy_cover(m, w, g).views.size();
  g.eliminate_redundant = true;
  const auto lean = sp::greedy_cover(m, w, g).views;
  const std::size_t n_lean = lean.size();
  const double greedy_s = std::chrono::duration<double>(Clock::now() - t0).count();
  // The local search from constrained greedy's (redundancy-eliminated) cover, as the planner runs it.
  sp::LocalSearchReport ls;
  const std::size_t n_local = sp::local_search_cover(m, w, g, lean, 20000, 60.0, 1, &ls).size();
  std::printf("%-28s   local search: %zu -> %zu views (%.1f %% fewer) in %.2f s, %llu swaps\n", name, n_lean, n_local,
              100.0 * (1.0 - double(n_local) / double(std::max<std::size_t>(1, n_lean))), ls.seconds,
              static_cast<unsigned long long>(ls.iterations));
  if (!g_exact) return;
  sp::CoverSettings e = g;
  e.mode = sp::CoverMode::exact;
  e.exact_time_limit_s = limit;
  sp::ExactReport rep;
  sp::exact_cover(m, w, e, {}, &rep);
  const double lb = std::ceil(rep.bound - 1e-6);
  std::printf("%-28s %5u x %-6zu %7.3f %4.2f | %6zu %6zu %7.3f | %6.0f %6.0f %6.3f %7.2f  %-34s| %6.3f %6.3f\n", name,
              m.n_rows, m.n_cols(), m.density(), t_r, n_greedy, n_lean, greedy_s, rep.objective, lb, rep.gap, rep.seconds,
              rep.status.substr(0, 34).c_str(), lb / static_cast<double>(n_greedy), rep.objective / static_cast<double>(n_greedy));
  std::printf("%-28s   presolve: rows %zu -> %zu (merged %zu, dominated %zu), columns %zu -> %zu (forced %zu, dominated %zu)%s, "
              "core %zu, Lagrangian bound %.1f, solves %zu, cuts %zu\n", "", rep.rows, rep.rows_after_presolve, rep.merged_rows, rep.dominated_rows, rep.columns,
              rep.columns_after_presolve, rep.forced_columns, rep.dominated_columns,
              rep.dominance_budget_hit ? " (budget hit)" : "", rep.core_columns, rep.lagrangian_bound, rep.solves,
              rep.connectivity_cuts);
  std::fflush(stdout);
}

}  // namespace

static int run_bench(int argc, char** argv) {
  double limit = 10.0;
  bool object = true, all_objects = false;
  std::string mesh_path = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes/bunny00.off";
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--time-limit") && i + 1 < argc) limit = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--mesh") && i + 1 < argc) mesh_path = argv[++i];
    else if (!std::strcmp(argv[i], "--skip-object")) object = false;
    else if (!std::strcmp(argv[i], "--no-exact")) g_exact = false;
    else if (!std::strcmp(argv[i], "--all-objects")) all_objects = true;
    else {
      std::fprintf(stderr, "usage: bench_cover [--time-limit S] [--mesh FILE] [--skip-object] [--all-objects] [--no-exact]\n");
      return 2;
    }
  }
  std::printf("time limit %.1f s per exact solve; e_v(bound) = ceil(bound)/n_greedy (a floor on greedy's efficiency), "
              "e_v(exact) = n_exact/n_greedy\n", limit);
  std::printf("%-28s %14s %7s %4s | %6s %6s %7s | %6s %6s %6s %7s  %-34s| %6s %6s\n", "instance", "rows x cols", "density",
              "t_r", "greedy", "+elim", "gr_s", "exact", "bound", "gap", "exact_s", "status", "ev_bnd", "ev_ex");
  run("random 0.24", random_matrix(400, 400, 0.24, 1), std::vector<double>(400, 1.0), 0.0, limit);
  run("random 0.64", random_matrix(400, 400, 0.64, 2), std::vector<double>(400, 1.0), 0.0, limit);

  const sp::SensorModel s = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const sp::ModelSpec spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  const double fs = sp::sensor_footprint_mm2(s, spec);
  const auto convex = patch_matrix(sp::convex_patch(std::sqrt(2.55 * fs), 0.04, 1.0), 400);
  run("convex patch D/W 0.04", convex.m, convex.w, 0.0, limit);
  run("convex patch D/W 0.04", convex.m, convex.w, 0.1, limit);
  for (double dw : {0.5, 1.0}) {
    const double plate = std::sqrt(0.55 * fs);
    const auto cav = patch_matrix(sp::cavity_patch(plate, 0.8 * plate, dw, 0.5), 400);
    char name[48];
    std::snprintf(name, sizeof name, "cavity D/W %.1f", dw);
    run(name, cav.m, cav.w, 0.0, limit);
    run(name, cav.m, cav.w, 0.1, limit);
  }
  std::vector<std::string> object_paths;
  if (object) object_paths.push_back(mesh_path);
  if (all_objects) {
    object_paths.clear();
    for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(mesh_path).parent_path()))
      if (e.path().extension() == ".off") object_paths.push_back(e.path().string());
    std::sort(object_paths.begin(), object_paths.end());
  }
  for (const auto& path : object_paths) {
    // A whole object, planned as scancell plans it (DECOUPLED, tilts, open-direction views), 5000 rough rows.
    sp::TriangleMesh mesh = sp::load_mesh(path);
    sp::apply_scale(mesh, sp::fit_scale(mesh, 200.0));
    sp::RoughModelOptions ro;
    ro.target_vertices = 5000;
    const sp::RoughModel rm = sp::build_rough_model(mesh, ro);
    const sp::OcclusionScene scene(rm.mesh());
    sp::ViewpointSettings vs;
    vs.position_decimation = 8;
    const auto cands = sp::generate_viewpoints(rm, scene, s, spec, vs);
    const auto m = sp::build_measurability(rm, scene, s, spec, cands);
    const std::string name = std::filesystem::path(path).stem().string() + " 200 mm, whole";
    run(name.c_str(), m, rm.area_mm2, 0.0, limit);
    run(name.c_str(), m, rm.area_mm2, 0.1, limit);
  }
  return 0;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_cover", [&] { return run_bench(argc, argv); });
}
