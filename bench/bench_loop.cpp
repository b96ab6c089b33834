// The daemon's closed loop against the cell oracle (issue 15 item 4): for every object, a whole job as an
// operator runs it on the demo cell (scancelld's JobRunner: plan, drive the simulated axes over the same
// driver code as real drives, scan with the virtual scanner, register, measure the rough model's coverage,
// replan for what is left, until done, stalled or jobs.max_rounds), then every executed view judged by the
// analytic measurability test on the fine mesh's vertices with the plate, as a share of what the cell oracle
// (bench/cell_oracle.hpp) reaches, and the job's total views against the oracle's views to 99 %.
//
//   bench_loop [--meshes DIR] [--only a,b] [--rough-vertices N] [--refine-mm E] [--max-rounds N]
//              [--placement auto|as_given] [--row-fraction F] [--normal-tolerance-mm T] [--oracle-decimation K] [--threads N] [--csv FILE] [--keep DIR]
//
// Shared meshes are scaled to a longest side of 200 mm and their edges refined to E mm (3): the fine model,
// which is both what the job is given and the object on the table (a job's rough model is made from it at
// N rows, 5000). The drives and the sweep run 10× faster than the real cell (as the tests' and the demo's
// simulated cells); cell times are at the real cell's speeds.
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "bench_common.hpp"
#include "bench_objects.hpp"
#include "cell_oracle.hpp"
#include "common/json_matrix.hpp"
#include "daemon/cell_io.hpp"
#include "daemon/job_runner.hpp"
#include "planner/placement.hpp"
#include "planner/sim/synthetic.hpp"

namespace sp = scancell::planner;
namespace dm = scancell::daemon;
namespace dr = scancell::drivers;
namespace fs = std::filesystem;
using scancell::bench::CellOracle;

namespace {

/// The views a job executed and stored, per round (round ≥ 0: not a rough scan's), in the object frame.
std::vector<std::vector<sp::Viewpoint>> executed_views(dm::Journal& journal, std::int64_t job) {
  std::vector<std::vector<sp::Viewpoint>> out;
  for (const auto& [plan, round] : journal.plan_rounds(job)) {
    if (round < 0) continue;
    if (static_cast<std::size_t>(round) >= out.size()) out.resize(static_cast<std::size_t>(round) + 1);
    for (const auto& v : journal.views(plan)) {
      if (!v.stored) continue;
      const auto pj = nlohmann::json::parse(v.pose_json);
      const Eigen::Matrix4d t = scancell::matrix4_from_row_major(pj.at("camera_to_object"), "camera_to_object");
      out[static_cast<std::size_t>(round)].push_back(
          sp::viewpoint_from_pose(t.topLeftCorner<3, 3>(), t.topRightCorner<3, 1>(), pj.at("scan_length_mm").get<double>()));
    }
  }
  return out;
}

void write_off(const sp::TriangleMesh& m, const fs::path& path) {
  std::ofstream f(path);
  f.precision(9);
  f << "OFF\n" << m.vertices.size() << ' ' << m.triangles.size() << " 0\n";
  for (const auto& v : m.vertices) f << v.x() << ' ' << v.y() << ' ' << v.z() << "\n";
  for (const auto& t : m.triangles) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::string meshes_dir = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes";
  std::string csv_path, keep_dir;
  std::set<std::string> only;
  std::size_t rough_vertices = 5000;
  int threads = 2, oracle_decimation = 4, max_rounds = 4;
  double refine_mm = 3.0;
  sp::CoverageOptions coverage;  // jobs.row_fraction, jobs.normal_tolerance_mm
  std::string placement;  // auto | as_given; empty: the shipped settings' placement.mode
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&] { return scancell::bench::option_value(argc, argv, i); };
    if (a == "--meshes") meshes_dir = value();
    else if (a == "--csv") csv_path = value();
    else if (a == "--keep") keep_dir = value();
    else if (a == "--rough-vertices") rough_vertices = std::stoull(value());
    else if (a == "--threads") threads = std::stoi(value());
    else if (a == "--refine-mm") refine_mm = std::stod(value());
    else if (a == "--max-rounds") max_rounds = std::stoi(value());
    else if (a == "--oracle-decimation") oracle_decimation = std::max(1, std::stoi(value()));
    else if (a == "--placement") placement = value();
    else if (a == "--normal-tolerance-mm") coverage.normal_tolerance_mm = std::stod(value());
    else if (a == "--row-fraction") coverage.row_fraction = std::stod(value());
    else if (a == "--only") {
      std::stringstream ss(value());
      for (std::string t; std::getline(ss, t, ',');) only.insert(t);
    } else {
      std::cerr << "usage: bench_loop [--meshes DIR] [--only a,b] [--rough-vertices N] [--refine-mm E] [--max-rounds N] "
                   "[--placement auto|as_given] [--row-fraction F] [--normal-tolerance-mm T] [--oracle-decimation K] [--threads N] [--csv FILE] [--keep DIR]\n";
      return 2;
    }
  }
  const std::string root = SCANCELL_SOURCE_DIR;
  dm::CellModels models;
  const sp::CellModel real_cell = sp::load_cell(root + "/config/cells/turntable-lift-tilt.yaml");
  models.cell = real_cell;
  for (auto& a : models.cell.axes) {
    a.max_speed *= 10.0;
    a.max_accel *= 20.0;
  }
  models.sensor = sp::load_sensor(root + "/config/sensors/line-scan-thesis.yaml");
  models.spec = sp::load_spec(root + "/config/spec/thesis.yaml");
  models.settings = sp::load_planner_settings(root + "/config/planner/default.yaml");
  if (placement == "auto" || placement == "as_given") models.settings.placement.automatic = placement == "auto";
  else if (!placement.empty()) {
    std::cerr << "--placement: auto or as_given, not " << placement << "\n";
    return 2;
  }

  std::vector<scancell::bench::BenchObject> objects = scancell::bench::shared_mesh_objects(meshes_dir, refine_mm);
  for (auto& o : scancell::bench::cad_objects(3.0)) objects.push_back(std::move(o));

  const fs::path work = keep_dir.empty() ? fs::temp_directory_path() / ("bench_loop_" + std::to_string(::getpid())) : fs::path(keep_dir);
  fs::create_directories(work);
  dr::DriverSetup setup;
  for (const auto& a : models.cell.axes) setup.axes[a.name] = dr::SimAxisConfig{};
  auto io = dm::open_cell_io(models.cell, setup, "bench drivers");
  dm::bring_up(*io, models.cell, std::chrono::milliseconds(10000));
  dm::Journal journal(work / "data");

  std::ofstream csv;
  if (!csv_path.empty()) {
    csv.open(csv_path);
    csv << "object,fine_vertices,reachable,oracle_views_95,oracle_views_99,oracle_views_99.9,end,rounds,round_views,"
           "single_shot_m_v_reachable,loop_m_v_reachable,loop_views,loop_over_oracle_99,verified_mv,verified_mv_reachable,"
           "round_gains_predicted_realized_mm2,rounds_under_20_percent,needs_attention_area_mm2,job_cell_time_s,oracle_cell_time_s,wall_s\n";
  }
  std::printf("closed loop on turntable-lift-tilt, placement %s, %zu rough rows, max_rounds %d, oracle 1 per %d fine vertices, %d threads\n",
              models.settings.placement.automatic ? "auto" : "as_given", rough_vertices, max_rounds, oracle_decimation, threads);
  std::printf("%-16s %6s %6s %15s %-8s %-18s %8s %8s %6s %6s %8s %8s %9s %9s %7s\n", "object", "fine", "reach",
              "oracle 95/99/999", "end", "views per round", "m_v_r_1", "m_v_r", "views", "ratio", "ver_m_v", "ver_r",
              "job_t_s", "orac_t_s", "wall_s");
  tbb::task_arena arena(threads);
  for (const auto& obj : objects) {
    if (!only.empty() && !only.count(obj.name)) continue;
    const auto t0 = std::chrono::steady_clock::now();
    const fs::path mesh_file = work / (obj.name + ".off");
    write_off(obj.make(), mesh_file);
    const sp::TriangleMesh fine_mesh = sp::load_mesh(mesh_file);  // what the job reads

    // The job, as scancellctl submit --mesh FILE --rough-vertices N on the demo cell.
    dm::JobSettings s;
    s.max_rounds = max_rounds;
    s.coverage = coverage;
    s.scan_speed_mm_s = 400.0;  // the demo's sweep (the real cell's 50 mm/s × the drives' factor)
    s.planner_threads = threads;
    s.next_setup_min_area_mm2 = 0.0;  // one setup: what this cell measures of the object as it lies
    s.jobs_dir = work / "data" / "jobs";
    dm::JobRequest r;
    r.mesh = mesh_file.string();
    r.rough_vertices = rough_vertices;
    dm::validate_request(r);
    const std::int64_t job = journal.create_job(r.mesh, r.to_json().dump());
    const sp::SensorModel sensor = models.sensor;
    auto heads = [&](const sp::TriangleMesh& scene, std::size_t object_triangles, const sp::CellModel& placed) {
      return dm::make_sim_head(sensor, scene, object_triangles, 7, &placed, nullptr);
    };
    dm::JobRunner runner(journal, models, io->positioner, heads, s, [](const dm::Progress&) {});
    std::atomic<int> stop{0};
    const dm::JobState end = runner.run(job, stop);
    const auto rec = journal.job(job);
    const nlohmann::json result = rec.result_json.empty() ? nlohmann::json::object() : nlohmann::json::parse(rec.result_json);

    // The same placement the job planned in (the planner is deterministic): the placed cell, for the plate and
    // the oracle's reach; at the real cell's speeds for cell times.
    const auto rounds = executed_views(journal, job);
    sp::RoughModelOptions ro;
    ro.target_vertices = rough_vertices;
    sp::ViewPlan plan;
    arena.execute([&] {
      plan = models.settings.placement.automatic
                 ? sp::plan_with_placement(fine_mesh, models.sensor, models.spec, models.settings, ro, threads, models.cell)
                 : sp::plan_views(fine_mesh, models.sensor, models.spec, models.settings, ro, threads, &models.cell);
    });
    sp::CellModel placed = *plan.cell;
    for (std::size_t k = 0; k < placed.axes.size(); ++k) {
      placed.axes[k].max_speed = real_cell.axes[k].max_speed;
      placed.axes[k].max_accel = real_cell.axes[k].max_accel;
    }
    if (rounds.empty() || rounds.front().size() != plan.views.size())
      std::fprintf(stderr, "%s: round 0 executed %zu views, the bench's plan has %zu (placement or plan differ)\n",
                   obj.name.c_str(), rounds.empty() ? std::size_t{0} : rounds.front().size(), plan.views.size());
    const sp::RoughModel fine = sp::make_rough_model(fine_mesh);
    sp::TriangleMesh scene_mesh = fine.mesh();
    sp::append_mesh(scene_mesh, sp::fixture_mesh(placed));
    const sp::OcclusionScene scene(scene_mesh);
    CellOracle oracle;
    std::vector<sp::Viewpoint> all;
    double single = 0.0, loop = 0.0;
    arena.execute([&] {
      oracle = scancell::bench::cell_oracle(fine_mesh, fine, scene, models.sensor, models.spec, &placed, oracle_decimation);
      for (const auto& rv : rounds) all.insert(all.end(), rv.begin(), rv.end());
      single = rounds.empty() ? 0.0 : scancell::bench::mv_of_reach(fine, scene, models.sensor, models.spec, rounds.front(), oracle);
      loop = scancell::bench::mv_of_reach(fine, scene, models.sensor, models.spec, all, oracle);
    });
    const double job_t = scancell::bench::cell_time_s(placed, all);
    std::string per_round;
    for (const auto& rv : rounds) per_round += (per_round.empty() ? "" : "+") + std::to_string(rv.size());
    const double verified = result.value("verified_mv", std::nan(""));
    const double ratio = oracle.views_99 ? double(all.size()) / double(oracle.views_99) : std::nan("");
    const std::string weak = result.contains("rounds_under_20_percent") ? result["rounds_under_20_percent"].dump() : "[]";
    const double attention = result.value("needs_attention_area_mm2", 0.0);
    const double wall = scancell::seconds_since(t0);
    // Each round's predicted and realized gain on the rough model (the job result's round_gains), mm2.
    std::string gains;
    for (const auto& g : result.value("round_gains", nlohmann::json::array()))
      gains += (gains.empty() ? "" : " ") + std::to_string(g.value("views", 0)) + ":" +
               std::to_string(std::lround(g.value("predicted_gain_mm2", 0.0))) + "/" +
               std::to_string(std::lround(g.value("realized_gain_mm2", 0.0)));
    std::printf("%-16s %6zu %6.3f %4zu/%4zu/%4zu %-8s %-18s %8.4f %8.4f %6zu %6.2f %8.4f %8.4f %9.0f %9.0f %7.0f  gains %s, weak rounds %s, "
                "needs attention %.0f mm2: %s\n",
                obj.name.c_str(), fine.size(), oracle.reachable(), oracle.views_95, oracle.views_99, oracle.views_999,
                dm::to_string(end), per_round.c_str(), single, loop, all.size(), ratio, verified,
                verified / oracle.reachable(), job_t, oracle.cell_time_s, wall, gains.c_str(), weak.c_str(), attention, rec.cause.c_str());
    std::fflush(stdout);
    if (csv)
      csv << obj.name << ',' << fine.size() << ',' << oracle.reachable() << ',' << oracle.views_95 << ',' << oracle.views_99
          << ',' << oracle.views_999 << ',' << dm::to_string(end) << ',' << rounds.size() << ',' << per_round << ','
          << single << ',' << loop << ',' << all.size() << ',' << ratio << ',' << verified << ','
          << verified / oracle.reachable() << ',' << gains << ',' << '"' << weak << '"' << ',' << attention << ',' << job_t << ','
          << oracle.cell_time_s << ',' << wall << '\n';
  }
  if (keep_dir.empty()) fs::remove_all(work);
  return 0;
}
