// The daemon's closed loop against the cell oracle (issue 15 item 4): for every object, a whole job as an
// operator runs it on the demo cell (scancelld's JobRunner: plan, drive the simulated axes over the same
// driver code as real drives, scan with the virtual scanner, register, measure the rough model's coverage,
// replan for what is left, until done, stalled or jobs.max_rounds), then every executed view judged by the
// analytic measurability test on the fine mesh's vertices with the plate, as a share of what the cell oracle
// (bench/cell_oracle.hpp, in the cell's own space; the oracle along the normals alone beside it) reaches, and
// the job's total views against the oracle's views to 99 %, and where the loss lies: the reach no executed
// view measures, by the state the job left the nearest rough row in, and how much of it faces the plate.
//
//   bench_loop [--meshes DIR] [--objects shared|generated] [--only a,b] [--rough-vertices N] [--refine-mm E] [--max-rounds N]
//              [--placement auto|as_given] [--row-fraction F] [--normal-tolerance-mm T] [--footprint-samples K]
//              [--oracle-decimation K] [--threads N] [--csv FILE] [--keep DIR] [--planner FILE]
//              [--min-gain-per-view-mm2 A] [--trigger drive_compare|daemon]
//
// --planner: planner settings other than config/planner/default.yaml; --min-gain-per-view-mm2: the replans'
// jobs.min_gain_per_view_mm2 (default the daemon's); --trigger: what triggers the scanner, the daemon's polled
// compare (default, scanner.trigger_source's: where profiles land, and with it later rounds, moves with the
// machine's load, a few views from run to run) or the drive's position compare (the same views on every run:
// for comparing two settings).
//
// --objects generated: the held-out shapes of generated_objects.hpp in place of the shared meshes and CAD parts.
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
#include <limits>
#include <memory>
#include <optional>
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
#include "generated_objects.hpp"
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


/// The fine mesh as the job reads it, at 9 digits (planner::write_off's µm would move the rough model's
/// decimation, and with it the plans docs/quality.md records).
void write_mesh(const sp::TriangleMesh& m, const fs::path& path) {
  std::ofstream f(path);
  f.precision(9);
  f << "OFF\n" << m.vertices.size() << ' ' << m.triangles.size() << " 0\n";
  for (const auto& v : m.vertices) f << v.x() << ' ' << v.y() << ' ' << v.z() << "\n";
  for (const auto& t : m.triangles) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
}

struct Options {
  std::string meshes_dir = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes";
  std::string objects = "shared";  // shared (the shared meshes, then the CAD parts) | generated (held out)
  std::string csv_path, keep_dir;
  std::set<std::string> only;
  std::size_t rough_vertices = 5000;
  int threads = 2, oracle_decimation = 4, max_rounds = 4;
  int footprint_samples = dm::JobSettings{}.footprint_samples;  // jobs.footprint_samples
  double refine_mm = 3.0;
  sp::CoverageOptions coverage;  // jobs.row_fraction, jobs.normal_tolerance_mm
  std::string placement;         // auto | as_given; empty: the shipped settings' placement.mode
  std::string planner_path = scancell::bench::shipped_settings_path();
  double min_gain_per_view_mm2 = dm::JobSettings{}.min_gain_per_view_mm2;
  bool drive_compare = false;  // --trigger daemon (the daemon's default; views vary with load) | drive_compare (the same views on every run)
};

/// The options, or nothing after printing the usage (an unknown option or a bad --placement).
std::optional<Options> parse_options(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&] { return scancell::bench::option_value(argc, argv, i); };
    if (a == "--meshes") o.meshes_dir = value();
    else if (a == "--objects") {
      o.objects = value();
      if (!scancell::bench::is_object_set(o.objects)) {
        std::cerr << "--objects: shared or generated, not " << o.objects << "\n";
        return std::nullopt;
      }
    }
    else if (a == "--csv") o.csv_path = value();
    else if (a == "--keep") o.keep_dir = value();
    else if (a == "--rough-vertices") o.rough_vertices = std::stoull(value());
    else if (a == "--threads") o.threads = std::stoi(value());
    else if (a == "--refine-mm") o.refine_mm = std::stod(value());
    else if (a == "--max-rounds") o.max_rounds = std::stoi(value());
    else if (a == "--oracle-decimation") o.oracle_decimation = std::max(1, std::stoi(value()));
    else if (a == "--placement") o.placement = value();
    else if (a == "--normal-tolerance-mm") o.coverage.normal_tolerance_mm = std::stod(value());
    else if (a == "--row-fraction") o.coverage.row_fraction = std::stod(value());
    else if (a == "--footprint-samples") o.footprint_samples = std::stoi(value());
    else if (a == "--planner") o.planner_path = value();
    else if (a == "--trigger") {
      const std::string t = value();
      if (t != "drive_compare" && t != "daemon") {
        std::cerr << "--trigger: drive_compare or daemon, not " << t << "\n";
        return std::nullopt;
      }
      o.drive_compare = t == "drive_compare";
    }
    else if (a == "--min-gain-per-view-mm2") o.min_gain_per_view_mm2 = std::stod(value());
    else if (a == "--only") {
      std::stringstream ss(value());
      for (std::string t; std::getline(ss, t, ',');) o.only.insert(t);
    } else {
      std::cerr << "usage: bench_loop [--meshes DIR] [--objects shared|generated] [--only a,b] [--rough-vertices N] [--refine-mm E] [--max-rounds N] "
                   "[--placement auto|as_given] [--row-fraction F] [--normal-tolerance-mm T] [--footprint-samples K] [--oracle-decimation K] "
                   "[--threads N] [--csv FILE] [--keep DIR] [--planner FILE] [--min-gain-per-view-mm2 A] [--trigger drive_compare|daemon]\n";
      return std::nullopt;
    }
  }
  if (!o.placement.empty() && o.placement != "auto" && o.placement != "as_given") {
    std::cerr << "--placement: auto or as_given, not " << o.placement << "\n";
    return std::nullopt;
  }
  return o;
}

/// The demo cell as the bench runs it: the models (drives 10x the real cell's speeds), the simulated
/// drives brought up, and a journal in `work`.
struct Rig {
  dm::CellModels models;
  sp::CellModel real_cell;
  std::unique_ptr<dm::CellIo> io;
  std::unique_ptr<dm::Journal> journal;
  fs::path work;
};

Rig make_rig(const Options& o) {
  const std::string root = SCANCELL_SOURCE_DIR;
  Rig r;
  r.real_cell = sp::load_cell(root + "/config/cells/turntable-lift-tilt.yaml");
  r.models.cell = r.real_cell;
  for (auto& a : r.models.cell.axes) {
    a.max_speed *= 10.0;
    a.max_accel *= 20.0;
  }
  r.models.sensor = sp::load_sensor(root + "/config/sensors/line-scan-thesis.yaml");
  r.models.spec = sp::load_spec(root + "/config/spec/thesis.yaml");
  r.models.settings = sp::load_planner_settings(o.planner_path);
  if (!o.placement.empty()) r.models.settings.placement.automatic = o.placement == "auto";
  r.work = o.keep_dir.empty() ? fs::temp_directory_path() / ("bench_loop_" + std::to_string(::getpid())) : fs::path(o.keep_dir);
  fs::create_directories(r.work);
  dr::DriverSetup setup;
  for (const auto& a : r.models.cell.axes) setup.axes[a.name] = dr::SimAxisConfig{};
  r.io = dm::open_cell_io(r.models.cell, setup, "bench drivers");
  dm::bring_up(*r.io, r.models.cell, std::chrono::milliseconds(10000));
  r.journal = std::make_unique<dm::Journal>(r.work / "data");
  return r;
}

/// The job, as scancellctl submit --mesh FILE --rough-vertices N runs it on the demo cell, to its end.
std::int64_t run_job(Rig& rig, const Options& o, const fs::path& mesh_file) {
  dm::JobSettings s;
  s.max_rounds = o.max_rounds;
  s.coverage = o.coverage;
  s.footprint_samples = o.footprint_samples;
  s.min_gain_per_view_mm2 = o.min_gain_per_view_mm2;
  s.drive_compare = o.drive_compare;
  s.scan_speed_mm_s = 400.0;  // the demo's sweep (the real cell's 50 mm/s × the drives' factor)
  s.planner_threads = o.threads;
  s.next_setup_min_area_mm2 = 0.0;  // one setup: what this cell measures of the object as it lies
  s.jobs_dir = rig.work / "data" / "jobs";
  dm::JobRequest r;
  r.mesh = mesh_file.string();
  r.rough_vertices = o.rough_vertices;
  dm::validate_request(r);
  const std::int64_t job = rig.journal->create_job(r.mesh, r.to_json().dump());
  auto heads = [&](const sp::TriangleMesh& scene, std::size_t object_triangles, const sp::CellModel& placed) {
    return dm::make_sim_head(rig.models.sensor, scene, object_triangles, 7, &placed, nullptr);
  };
  dm::JobRunner runner(*rig.journal, rig.models, rig.io->positioner, heads, s, [](const dm::Progress&) {});
  std::atomic<int> stop{0};
  runner.run(job, stop);
  return job;
}

/// A finished job's executed views judged against the cell oracle in the placement the job planned in.
struct Judged {
  CellOracle oracle, along_normal;  // in the cell's own space; along the normals alone (cell_oracle.hpp)
  double loop_normal = 0.0;         // m_v of the along-normal oracle's reach at the end
  std::vector<std::vector<sp::Viewpoint>> rounds;
  std::size_t fine_rows = 0, views = 0;
  double single = 0.0, loop = 0.0;  // m_v of the reach after round 0, at the end
  /// The analytic test of every executed view on the whole fine object (not only the oracle's reach): the
  /// figure the daemon's verified m_v is compared with (issue 15 item 6). Views the oracle has no like of
  /// (oblique, into a bore) measure area outside its reach, which m_v of the reach leaves out.
  double analytic_mv = 0.0;
  double job_cell_time_s = 0.0;
  /// At equal completeness: the oracle's greedy views to the job's m_v of the reach, and a greedy cover of
  /// the job's own executed views to it (how many of them the job would have needed, had it known).
  std::size_t oracle_views_to_loop = 0, own_views_to_loop = 0;
  /// Where the loop's loss lies (share of the oracle's reach the executed views do not measure, by the state the
  /// job left the nearest rough row in): counted measured (the scans filled jobs.row_fraction of its footprint),
  /// needs attention (given up), unmeasurable (no candidate of round 0 measures it, so no replan chases it), or
  /// otherwise unmeasured (open).
  double lost_in_measured = 0.0, lost_in_attention = 0.0, lost_in_unmeasurable = 0.0, lost_in_open = 0.0;
  double lost_facing_down = 0.0;  // of the loss, surface facing the plate (n_z < -0.5 on the table)
  /// Of the loss, the rows judge_model adds for the fine vertices on a crease (each judged by one face).
  double lost_on_crease = 0.0;
};

/// The rough row nearest `p` and its squared distance (mm²); the lowest index among equally near rows. A
/// plain scan: the bench asks this of the few hundred vertices a loop leaves and the rows it lists.
std::pair<std::size_t, double> nearest_row(const sp::RoughModel& rough, const Eigen::Vector3d& p) {
  std::pair<std::size_t, double> best{0, std::numeric_limits<double>::infinity()};
  for (std::size_t r = 0; r < rough.size(); ++r)
    if (const double d = (rough.points[r] - p).squaredNorm(); d < best.second) best = {r, d};
  return best;
}

/// Rough-model rows listed in a job's .xyz file (x y z first on each line): one flag per row of `rough`.
std::vector<std::uint8_t> rows_listed(const sp::RoughModel& rough, const std::string& path) {
  std::vector<std::uint8_t> out(rough.size(), 0);
  std::ifstream f(path);
  if (!f) std::fprintf(stderr, "the job's row file '%s' cannot be read: its rows count as measured in the loss split\n", path.c_str());
  for (std::string line; std::getline(f, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    Eigen::Vector3d p;
    if (!(ss >> p.x() >> p.y() >> p.z())) continue;
    if (const auto [r, d2] = nearest_row(rough, p); d2 < 1e-4) out[r] = 1;  // within 0.01 mm: the row written
  }
  return out;
}

/// Judged's loss by row state: each fine vertex of the oracle's reach that no executed view measures, by the
/// state the job left its nearest rough row in (the job's unmeasured and needs-attention files, round 0's rows
/// without a candidate), and whether it faces the plate.
void add_loss_by_row_state(Judged& j, const sp::RoughModel& fine, std::size_t vertex_rows, const sp::MeasurabilityMatrix& mm,
                           const sp::ViewPlan& plan, const sp::CellModel& placed, const nlohmann::json& result) {
  std::vector<std::uint8_t> got(fine.size(), 0);
  for (const auto& c : mm.columns) c.for_each([&](std::uint32_t r) { got[r] = 1; });
  const auto unmeasured = rows_listed(plan.rough, result.value("unmeasured_file", std::string()));
  const auto attention = rows_listed(plan.rough, result.value("needs_attention_file", std::string()));
  std::vector<std::uint8_t> no_candidate(plan.rough.size(), 0);
  for (const auto r : plan.cover.unmeasurable_rows) no_candidate[r] = 1;
  for (std::size_t r = 0; r < fine.size(); ++r) {
    if (!j.oracle.reach[r] || got[r]) continue;
    const std::size_t best = nearest_row(plan.rough, fine.points[r]).first;
    const double a = fine.area_mm2[r] / j.oracle.reach_area_mm2;
    (attention[best]      ? j.lost_in_attention
     : no_candidate[best] ? j.lost_in_unmeasurable
     : unmeasured[best]   ? j.lost_in_open
                          : j.lost_in_measured) += a;
    if ((placed.object_on_table.linear() * fine.normals[r]).z() < -0.5) j.lost_facing_down += a;
    if (r >= vertex_rows) j.lost_on_crease += a;
  }
}

Judged judge(Rig& rig, const Options& o, std::int64_t job, const sp::TriangleMesh& fine_mesh, const std::string& name,
             const nlohmann::json& result) {
  Judged j;
  j.rounds = executed_views(*rig.journal, job);
  // The placement the job planned in (the planner is deterministic): the placed cell, for the plate and the
  // oracle's reach; at the real cell's speeds for cell times.
  const dm::CellModels& m = rig.models;
  sp::RoughModelOptions ro;
  ro.target_vertices = o.rough_vertices;
  sp::PlannerSettings as_job = m.settings;  // a job covers without the between-view constraint (JobRunner::read_request)
  as_job.cover = sp::registered_to_model(m.settings.cover);
  sp::ViewPlan plan = as_job.placement.automatic ? sp::plan_with_placement(fine_mesh, m.sensor, m.spec, as_job, ro, o.threads, m.cell)
                                                 : sp::plan_views(fine_mesh, m.sensor, m.spec, as_job, ro, o.threads, &m.cell);
  sp::CellModel placed = *plan.cell;
  for (std::size_t k = 0; k < placed.axes.size(); ++k) {
    placed.axes[k].max_speed = rig.real_cell.axes[k].max_speed;
    placed.axes[k].max_accel = rig.real_cell.axes[k].max_accel;
  }
  if (j.rounds.empty() || j.rounds.front().size() != plan.views.size())
    std::fprintf(stderr, "%s: round 0 executed %zu views, the bench's plan has %zu (placement or plan differ)\n", name.c_str(),
                 j.rounds.empty() ? std::size_t{0} : j.rounds.front().size(), plan.views.size());
  const sp::RoughModel fine = scancell::bench::judge_model(fine_mesh);
  sp::TriangleMesh scene_mesh = fine_mesh;
  sp::append_mesh(scene_mesh, sp::fixture_mesh(placed));
  const sp::OcclusionScene scene(scene_mesh);
  j.oracle = scancell::bench::cell_oracle(fine_mesh, fine, scene, m.sensor, m.spec, &placed, o.oracle_decimation,
                                          &scancell::bench::shipped_cell_space(), &j.along_normal);
  std::vector<sp::Viewpoint> all;
  for (const auto& rv : j.rounds) all.insert(all.end(), rv.begin(), rv.end());
  j.single = j.rounds.empty() ? 0.0 : scancell::bench::mv_of_reach(fine, scene, m.sensor, m.spec, j.rounds.front(), j.oracle);
  j.loop = scancell::bench::mv_of_reach(fine, scene, m.sensor, m.spec, all, j.oracle);
  j.loop_normal = scancell::bench::mv_of_reach(fine, scene, m.sensor, m.spec, all, j.along_normal);
  if (!all.empty()) {
    const auto mm = sp::build_measurability(fine, scene, m.sensor, m.spec, all);
    std::vector<std::uint32_t> order(all.size());
    for (std::uint32_t k = 0; k < order.size(); ++k) order[k] = k;
    j.analytic_mv = scancell::bench::progression(mm, order, fine.area_mm2, std::vector<std::uint8_t>(fine.size(), 1), fine.total_area_mm2).back();
    std::vector<double> reach_area(fine.size(), 0.0);
    for (std::size_t r = 0; r < fine.size(); ++r) reach_area[r] = j.oracle.reach[r] ? fine.area_mm2[r] : 0.0;
    sp::CoverSettings cs;
    cs.mode = sp::CoverMode::greedy;
    cs.eliminate_redundant = false;
    const auto own = sp::greedy_cover(mm, reach_area, cs);
    const auto own_prog = scancell::bench::progression(mm, own.views, fine.area_mm2, j.oracle.reach, j.oracle.reach_area_mm2);
    j.own_views_to_loop = scancell::bench::views_to(own_prog, j.loop);
    j.oracle_views_to_loop = scancell::bench::views_to(j.oracle.progression, j.loop);
    add_loss_by_row_state(j, fine, fine_mesh.vertices.size(), mm, plan, placed, result);
  }
  j.job_cell_time_s = scancell::bench::cell_time_s(placed, all);
  j.fine_rows = fine.size();
  j.views = all.size();
  return j;
}

}  // namespace

static int run_bench(int argc, char** argv) {
  const std::optional<Options> opt = parse_options(argc, argv);
  if (!opt) return 2;
  const Options& o = *opt;
  const std::vector<scancell::bench::BenchObject> objects =
      scancell::bench::only_these(scancell::bench::objects_to_plan(o.objects, o.meshes_dir, o.refine_mm), o.only);
  Rig rig = make_rig(o);

  std::ofstream csv;
  if (!o.csv_path.empty()) {
    csv.open(o.csv_path);
    csv << "object,fine_vertices,reachable,oracle_views_95,oracle_views_99,oracle_views_99.9,end,rounds,round_views,"
           "single_shot_m_v_reachable,loop_m_v_reachable,loop_views,loop_over_oracle_99,verified_mv,verified_mv_reachable,analytic_mv,"
           "round_gains_predicted_realized_mm2,rounds_under_20_percent,needs_attention_area_mm2,job_cell_time_s,oracle_cell_time_s,"
           "oracle_views_to_loop_m_v,own_views_to_loop_m_v,wall_s,normal_oracle_reachable,normal_oracle_views_99,"
           "loop_m_v_normal_reachable,loop_over_normal_oracle_99,lost_in_measured_rows,lost_in_attention_rows,"
           "lost_in_no_candidate_rows,lost_in_open_rows,lost_facing_down,lost_on_crease\n";
  }
  std::printf("closed loop on turntable-lift-tilt, placement %s, %zu rough rows, max_rounds %d, oracle 1 per %d fine vertices, %d threads\n",
              rig.models.settings.placement.automatic ? "auto" : "as_given", o.rough_vertices, o.max_rounds, o.oracle_decimation, o.threads);
  std::printf("%-16s %6s %6s %15s %-8s %-18s %8s %8s %6s %6s %8s %8s %8s %9s %9s %7s\n", "object", "fine", "reach",
              "oracle 95/99/999", "end", "views per round", "m_v_r_1", "m_v_r", "views", "ratio", "ver_m_v", "ver_r", "anal_m_v",
              "job_t_s", "orac_t_s", "wall_s");
  tbb::task_arena arena(o.threads);
  for (const auto& obj : objects) {
    const auto t0 = std::chrono::steady_clock::now();
    const fs::path mesh_file = rig.work / (obj.name + ".off");
    write_mesh(obj.make(), mesh_file);
    const sp::TriangleMesh fine_mesh = sp::load_mesh(mesh_file);  // what the job reads
    const std::int64_t job = run_job(rig, o, mesh_file);
    const dm::JobRecord rec = rig.journal->job(job);
    const nlohmann::json result = rec.result_json.empty() ? nlohmann::json::object() : nlohmann::json::parse(rec.result_json);
    Judged j;
    arena.execute([&] { j = judge(rig, o, job, fine_mesh, obj.name, result); });
    const CellOracle& oracle = j.oracle;
    std::string per_round;
    for (const auto& rv : j.rounds) per_round += (per_round.empty() ? "" : "+") + std::to_string(rv.size());
    const double verified = result.value("verified_mv", std::nan(""));
    const double ratio = oracle.views_99 ? double(j.views) / double(oracle.views_99) : std::nan("");
    const double ratio_normal = j.along_normal.views_99 ? double(j.views) / double(j.along_normal.views_99) : std::nan("");
    const std::string weak = result.contains("rounds_under_20_percent") ? result["rounds_under_20_percent"].dump() : "[]";
    const double attention = result.value("needs_attention_area_mm2", 0.0);
    const double wall = scancell::seconds_since(t0);
    // Each round's predicted and realized gain on the rough model (the job result's round_gains), mm2.
    std::string gains;
    for (const auto& g : result.value("round_gains", nlohmann::json::array()))
      gains += (gains.empty() ? "" : " ") + std::to_string(g.value("views", 0)) + ":" +
               std::to_string(std::lround(g.value("predicted_gain_mm2", 0.0))) + "/" +
               std::to_string(std::lround(g.value("realized_gain_mm2", 0.0)));
    std::printf("%-16s %6zu %6.3f %4zu/%4zu/%4zu %-8s %-18s %8.4f %8.4f %6zu %6.2f %8.4f %8.4f %8.4f %9.0f %9.0f %7.0f  to the job's m_v: oracle %zu views, "
                "the job's own %zu; along normals: reach %.3f views %zu/%zu/%zu m_v_r %.4f ratio %.2f; gains %s, weak rounds %s, "
                "needs attention %.0f mm2; lost by row state: measured %.4f attention %.4f no candidate %.4f open %.4f, facing down %.4f, on a crease %.4f: %s\n",
                obj.name.c_str(), j.fine_rows, oracle.reachable(), oracle.views_95, oracle.views_99, oracle.views_999,
                dm::to_string(rec.state), per_round.c_str(), j.single, j.loop, j.views, ratio, verified,
                verified / oracle.reachable(), j.analytic_mv, j.job_cell_time_s, oracle.cell_time_s, wall, j.oracle_views_to_loop,
                j.own_views_to_loop, j.along_normal.reachable(), j.along_normal.views_95, j.along_normal.views_99,
                j.along_normal.views_999, j.loop_normal, ratio_normal, gains.c_str(), weak.c_str(), attention,
                j.lost_in_measured, j.lost_in_attention, j.lost_in_unmeasurable, j.lost_in_open, j.lost_facing_down, j.lost_on_crease, rec.cause.c_str());
    std::fflush(stdout);
    if (csv)
      csv << obj.name << ',' << j.fine_rows << ',' << oracle.reachable() << ',' << oracle.views_95 << ',' << oracle.views_99
          << ',' << oracle.views_999 << ',' << dm::to_string(rec.state) << ',' << j.rounds.size() << ',' << per_round << ','
          << j.single << ',' << j.loop << ',' << j.views << ',' << ratio << ',' << verified << ','
          << verified / oracle.reachable() << ',' << j.analytic_mv << ',' << gains << ',' << '"' << weak << '"' << ',' << attention << ','
          << j.job_cell_time_s << ',' << oracle.cell_time_s << ',' << j.oracle_views_to_loop << ',' << j.own_views_to_loop << ','
          << wall << ',' << j.along_normal.reachable() << ',' << j.along_normal.views_99 << ',' << j.loop_normal << ','
          << ratio_normal << ',' << j.lost_in_measured << ',' << j.lost_in_attention << ',' << j.lost_in_unmeasurable << ','
          << j.lost_in_open << ',' << j.lost_facing_down << ',' << j.lost_on_crease << '\n';
  }
  if (o.keep_dir.empty()) fs::remove_all(rig.work);
  return 0;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_loop", [&] { return run_bench(argc, argv); });
}
