// Plan quality against an oracle in the same configuration space (issue 15): for every object, free space and
// each shipped cell, the planner's single-shot plan from a rough model against dense candidates made from the
// fine mesh itself, both judged by the analytic measurability test (frustum, bi-static visibility, eq. 3.4,
// eq. 3.8) on the fine mesh's vertices, area-weighted, with the cell's fixtures (the plate) in the scene.
//
//   bench_cell [--meshes DIR] [--only a,b] [--cell FILE|none]... [--rough-vertices N] [--threads N] [--csv FILE]
//              [--settings FILE] [--oracle-decimation K] [--refine-mm E]
//
// Shared meshes are scaled to a longest side of 200 mm and their edges refined to E mm (2): the fine model.
//
// Oracle (shared/design/QUALITY-TARGETS.md): one view per K-th fine vertex (K = 4) along its normal at
// f_d·R_o, scan length from the density spec; free space: 8 twists; on turntable_lift_tilt the one twist the
// cell reaches (baseline along world +Y, camera on +X), tilt clamped to the tilt axis' range. Greedy cover.
// The oracle ignores axis ranges other than the tilt and scanner-body collisions: an upper bound on reach.
// Columns: views to 95/99/99.9 % of the oracle-reachable area; the plan's views, its m_v of that area, its
// views over the oracle's to 99 %; cell time (moves + sweeps, travel-ordered) for both.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "planner/kinematics/cell.hpp"
#include "planner/config.hpp"
#include "planner/core/cover.hpp"
#include "planner/core/measurability.hpp"
#include "planner/plan.hpp"
#include "planner/sim/synthetic.hpp"
#include "bench_common.hpp"
#include "bench_objects.hpp"
#include "cell_oracle.hpp"

namespace sp = scancell::planner;
namespace fs = std::filesystem;
namespace bench = scancell::bench;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

}  // namespace

int main(int argc, char** argv) {
  std::string meshes_dir = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes";
  std::string csv_path, settings_file = std::string(SCANCELL_SOURCE_DIR) + "/config/planner/default.yaml";
  std::set<std::string> only;
  std::vector<std::string> cells;
  std::size_t rough_vertices = 5000;
  int threads = 0, oracle_decimation = 4;
  double refine_mm = 2.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&] { return bench::option_value(argc, argv, i); };
    if (a == "--meshes") meshes_dir = value();
    else if (a == "--csv") csv_path = value();
    else if (a == "--cell") cells.push_back(value());
    else if (a == "--settings") settings_file = value();
    else if (a == "--rough-vertices") rough_vertices = std::stoull(value());
    else if (a == "--threads") threads = std::stoi(value());
    else if (a == "--refine-mm") refine_mm = std::stod(value());
    else if (a == "--oracle-decimation") oracle_decimation = std::max(1, std::stoi(value()));
    else if (a == "--only") {
      std::stringstream ss(value());
      for (std::string t; std::getline(ss, t, ',');) only.insert(t);
    } else {
      std::cerr << "usage: bench_cell [--meshes DIR] [--only a,b] [--cell FILE|none]... [--rough-vertices N] "
                   "[--settings FILE] [--oracle-decimation K] [--refine-mm E] [--threads N] [--csv FILE]\n";
      return 2;
    }
  }
  if (cells.empty()) cells = {"none", std::string(SCANCELL_SOURCE_DIR) + "/config/cells/turntable-lift-tilt.yaml"};
  const auto sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const auto spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  auto settings = sp::load_planner_settings(settings_file);
  settings.keep_candidates = true;

  std::vector<bench::BenchObject> objects = bench::shared_mesh_objects(meshes_dir, refine_mm);
  for (auto& o : bench::cad_objects(3.0)) objects.push_back(std::move(o));

  const int n_threads = threads > 0 ? threads : tbb::info::default_concurrency();
  tbb::task_arena arena(n_threads);
  std::ofstream csv;
  if (!csv_path.empty()) {
    csv.open(csv_path);
    csv << "object,cell,fine_vertices,reachable,oracle_views_95,oracle_views_99,oracle_views_99.9,plan_views,"
           "plan_m_v_reachable,plan_over_oracle_99,plan_s,plan_cell_time_s,oracle_cell_time_s,candidates_reach,"
           "lost_range_incidence,lost_plate,lost_axes,lost_collision\n";
  }
  std::printf("sensor %s, spec %.3f mm / %.1f samples/mm2, rough %zu vertices, oracle 1 per %d fine vertices, "
              "%d threads\n",
              sensor.name.c_str(), spec.precision_mm, spec.density_per_mm2, rough_vertices, oracle_decimation, n_threads);
  std::printf("%-16s %-20s %6s %6s %15s %6s %6s %8s %8s %6s %7s %10s %10s\n", "object", "cell", "fine", "reach",
              "oracle 95/99/999", "cands", "plan", "cand_rch", "m_v_rch", "ratio", "plan_s", "cell_t_s", "orac_t_s");
  arena.execute([&] {
    for (const auto& obj : objects) {
      if (!only.empty() && !only.count(obj.name)) continue;
      const sp::TriangleMesh fine_mesh = obj.make();
      for (const auto& cell_file : cells) {
        std::optional<sp::CellModel> cell;
        if (cell_file != "none") cell = sp::load_cell(cell_file);
        sp::RoughModelOptions ro;
        ro.target_vertices = rough_vertices;
        const auto t0 = Clock::now();
        const sp::ViewPlan plan = sp::plan_views(fine_mesh, sensor, spec, settings, ro, n_threads, cell ? &*cell : nullptr);
        const double plan_s = since(t0);
        // The fine mesh's rows, in the plan's object frame, with the plate.
        const sp::RoughModel fine = sp::make_rough_model(fine_mesh);
        sp::TriangleMesh scene_mesh = fine.mesh();
        if (plan.cell) sp::append_mesh(scene_mesh, sp::fixture_mesh(*plan.cell));
        const sp::OcclusionScene scene(scene_mesh);
        const bench::CellOracle oracle =
            bench::cell_oracle(fine_mesh, fine, scene, sensor, spec, plan.cell ? &*plan.cell : nullptr, oracle_decimation);
        const std::vector<std::uint8_t>& reach = oracle.reach;
        const double reach_area = oracle.reach_area_mm2;
        const double total = oracle.total_area_mm2;
        const auto pm = sp::build_measurability(fine, scene, sensor, spec, plan.views);
        std::vector<std::uint32_t> all(plan.views.size());
        for (std::uint32_t k = 0; k < all.size(); ++k) all[k] = k;
        const auto pprog = bench::progression(pm, all, fine.area_mm2, reach, reach_area);
        const double mv = pprog.empty() ? 0.0 : pprog.back();
        // The plan's own views re-ordered greedily on the fine model: how many of them reach 99 % of the oracle's
        // reach (the rest of the plan chases the rough model's last rows).
        std::size_t plan99 = 0;
        {
          sp::CoverSettings gs;
          gs.mode = sp::CoverMode::greedy;
          gs.eliminate_redundant = false;
          std::vector<double> masked(fine.size());
          for (std::size_t r = 0; r < fine.size(); ++r) masked[r] = reach[r] ? fine.area_mm2[r] : 0.0;
          const auto pc = sp::greedy_cover(pm, masked, gs);
          plan99 = bench::views_to(bench::progression(pm, pc.views, fine.area_mm2, reach, reach_area), 0.99);
        }
        // What the plan's whole candidate set could reach on the fine model: below the oracle's reach means the
        // candidates lack views; above the plan's m_v means the cover (or the rough model's estimate) fell short.
        const auto cm = sp::build_measurability(fine, scene, sensor, spec, plan.candidate_views);
        double cand_reach = 0.0;
        {
          std::vector<std::uint8_t> got(fine.size(), 0);
          for (const auto& c : cm.columns) c.for_each([&](std::uint32_t r) { got[r] = 1; });
          for (std::size_t r = 0; r < fine.size(); ++r) cand_reach += got[r] && reach[r] ? fine.area_mm2[r] : 0.0;
          cand_reach /= reach_area;
        }
        const double est = plan.cover.cumulative_fraction.empty() ? 0.0 : plan.cover.cumulative_fraction.back();
        const std::size_t o95 = oracle.views_95, o99 = oracle.views_99, o999 = oracle.views_999;
        const double plan_t = plan.cell ? plan.cell_report.travel_s + plan.cell_report.scan_s : std::nan("");
        const double oracle_t = oracle.cell_time_s;
        const double lost_range = oracle.lost_range, lost_plate = oracle.lost_plate, lost_axes = oracle.lost_axes,
                     lost_collision = oracle.lost_collision;
        const std::string cname = cell ? cell->name : "free";
        const double ratio = o99 ? double(plan.views.size()) / o99 : std::nan("");
        std::printf("%-16s %-20s %6zu %6.3f %4zu/%4zu/%4zu %6zu %6zu %8.4f %8.4f %6.2f %7.1f %10.0f %10.0f  est %.4f  plan_to_99 %zu  "
                    "lost: range/incidence %.4f plate %.4f axes %.4f collision %.4f\n",
                    obj.name.c_str(), cname.c_str(), fine.size(), total > 0 ? reach_area / total : 0.0, o95, o99, o999,
                    plan.candidate_views.size(), plan.views.size(), cand_reach, mv, ratio, plan_s, plan_t, oracle_t, est,
                    plan99, lost_range, lost_plate, lost_axes, lost_collision);
        std::fflush(stdout);
        if (csv)
          csv << obj.name << ',' << cname << ',' << fine.size() << ',' << reach_area / fine.total_area_mm2 << ',' << o95
              << ',' << o99 << ',' << o999 << ',' << plan.views.size() << ',' << mv << ',' << ratio << ',' << plan_s
              << ',' << plan_t << ',' << oracle_t << ',' << cand_reach << ',' << lost_range << ',' << lost_plate << ','
              << lost_axes << ',' << lost_collision << '\n';
      }
    }
  });
  return 0;
}
