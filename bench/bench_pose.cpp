// Pose-error benchmark (issue 5, thesis fig. 7.12-7.15): plans executed under sampled positioner error,
// Monte Carlo over the error, without and with the 7.4.7 countermeasures sized for σ_a = 0.5°, σ_p = 0.5 mm.
//   bench_pose [--meshes DIR] [--only a,b] [--trials N] [--threads N] [--stress]
// --stress replaces the grid by larger errors (2-4°, 2-5 mm) to find where plans break.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "planner/plan.hpp"
#include "planner/kinematics/pose_error.hpp"
#include "planner/sim/synthetic.hpp"
#include "planner/sim/verify.hpp"
#include "bench/bench_common.hpp"

namespace sp = scancell::planner;

static int run_bench(int argc, char** argv) {
  std::string meshes = std::string(SCANCELL_SOURCE_DIR) + "/../shared/meshes";
  std::set<std::string> only = {"convex-patch", "fandisk", "mushroom", "bunny00"};
  int trials = 8, threads = 0;
  bool stress = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--meshes" && i + 1 < argc) meshes = argv[++i];
    else if (a == "--trials" && i + 1 < argc) trials = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--stress") stress = true;
    else if (a == "--only" && i + 1 < argc) {
      only.clear();
      std::stringstream ss(argv[++i]);
      for (std::string t; std::getline(ss, t, ',');) only.insert(t);
    } else {
      std::fprintf(stderr, "usage: bench_pose [--meshes DIR] [--only a,b] [--trials N] [--threads N] [--stress]\n");
      return 2;
    }
  }
  const sp::SensorModel sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  const sp::ModelSpec spec = sp::load_spec(std::string(SCANCELL_SOURCE_DIR) + "/config/spec/thesis.yaml");
  const double deg = std::numbers::pi / 180.0;
  const sp::PoseErrorModel design{0.5, 0.5 * deg, 0.0};
  const sp::Countermeasures cm = sp::countermeasures_for(sensor, design, 1.02);
  std::printf("countermeasures for σ_p 0.5 mm, σ_a 0.5°: frustum_detune %.4f, compliance_buffer %.4f, dof_margin_mm %.3f, "
              "visibility_margin_mm %.3f; %d trials per point\n",
              cm.frustum_detune, cm.compliance_buffer, cm.dof_margin_mm, cm.visibility_margin_mm, trials);
  std::vector<std::pair<std::string, std::function<sp::TriangleMesh()>>> objects;
  const double fs = sp::sensor_footprint_mm2(sensor, spec);
  objects.push_back({"convex-patch", [&] { return sp::convex_patch(std::sqrt(2.55 * fs), 0.04, 1.0); }});
  for (const char* n : {"fandisk", "mushroom", "bunny00", "elephant", "cow"}) {
    const std::string name = n;
    objects.push_back({name, [=] {
                         sp::TriangleMesh m = sp::load_mesh(meshes + "/" + name + ".off");
                         sp::apply_scale(m, sp::fit_scale(m, 200.0));
                         return sp::refine_edges(m, 2.0);
                       }});
  }
  std::vector<sp::PoseErrorModel> grid;
  if (stress) {
    grid = {{0.0, 2.0 * deg, 0.0}, {0.0, 4.0 * deg, 0.0}, {2.0, 0.0, 0.0}, {5.0, 0.0, 0.0}, {2.0, 2.0 * deg, 2.0 * deg}};
  } else {
    for (double a : {0.0, 0.1, 0.25, 0.5, 1.0}) grid.push_back({0.0, a * deg, 0.0});
    for (double p : {0.1, 0.5, 1.0}) grid.push_back({p, 0.0, 0.0});
    grid.push_back(design);
  }

  tbb::task_arena arena(threads > 0 ? threads : tbb::info::default_concurrency());
  std::printf("%-14s %-16s %6s %9s %9s %9s | %8s %8s %8s\n", "object", "plan", "views", "sigma_p", "sigma_a", "sigma_t",
              "m_v_mean", "m_v_sd", "m_v_min");
  arena.execute([&] {
    for (const auto& [name, make] : objects) {
      if (!only.count(name)) continue;
      const sp::TriangleMesh fine = make();
      sp::RoughModelOptions rough;
      rough.rho_rel = -5.0;
      rough.normal_noise_mm = 0.005 * sensor.range_min_mm;
      for (bool counter : {false, true}) {
        sp::PlannerSettings settings;
        if (counter) settings.matrix.countermeasures = cm;
        const sp::ViewPlan plan = sp::plan_views(fine, sensor, spec, settings, rough);
        std::vector<sp::ScanPose> poses;
        for (const auto& v : plan.views) poses.push_back(sp::scan_pose(v));
        for (const auto& e : grid) {
          sp::VerifyOptions o;
          o.pose_error = e;
          const auto mc = sp::verify_monte_carlo(fine, sensor, spec, poses, o, e.zero() ? 1 : trials);
          std::printf("%-14s %-16s %6zu %9.2f %9.2f %9.2f | %8.4f %8.4f %8.4f\n", name.c_str(),
                      counter ? "countermeasures" : "plain", plan.views.size(), e.sigma_p_mm, e.sigma_a_rad / deg,
                      e.sigma_t_rad / deg, mc.mean, mc.sd, mc.min);
          std::fflush(stdout);
        }
      }
    }
  });
  return 0;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_pose", [&] { return run_bench(argc, argv); });
}
