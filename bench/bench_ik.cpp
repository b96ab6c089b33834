// The arm cell's inverse kinematics: closed form (the Universal Robots geometry, planner/kinematics/arm_ik.hpp)
// against the numerical solver (KDL's LMA from a few seeds, then Newton), on the same camera poses, in the same
// run. The poses are drawn as the planner makes views (sim/synthetic.hpp view_like_poses: 200-400 mm from a
// point 80 mm above the plate, any azimuth, elevations from -10° to 75°, any twist). Prints, per solver, the
// poses solved, the solves per second (one thread) and the time ratio; and the poses one solver reaches and the
// other does not (exit 1 when the numerical solver reaches one the closed form misses).
//   bench_ik [--cell FILE] [--poses N] [--seed S]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "planner/kinematics/cell.hpp"
#include "planner/sim/synthetic.hpp"
#include "bench/bench_common.hpp"

namespace sp = scancell::planner;
using Clock = std::chrono::steady_clock;

namespace {

struct Run {
  std::vector<char> solved;
  double seconds = 0.0;
  double worst_error = 0.0;  // mm or rad, of the solutions
};

Run solve_all(const sp::CellModel& cell, const std::vector<Eigen::Isometry3d>& poses) {
  Run r;
  const auto t0 = Clock::now();
  std::vector<sp::IkResult> results;
  results.reserve(poses.size());
  for (const auto& p : poses) results.push_back(sp::inverse_kinematics(cell, p, 40.0));
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    r.solved.push_back(results[i].ok);
    if (!results[i].ok) continue;
    const Eigen::Isometry3d got = sp::forward_kinematics(cell, results[i].q);
    r.worst_error = std::max({r.worst_error, (got.translation() - poses[i].translation()).norm(),
                              Eigen::AngleAxisd(got.linear().transpose() * poses[i].linear()).angle()});
  }
  return r;
}

}  // namespace

static int run_bench(int argc, char** argv) {
  std::string cell_file = std::string(SCANCELL_SOURCE_DIR) + "/config/cells/arm-turntable.yaml";
  int n = 2000;
  unsigned seed = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--cell" && i + 1 < argc) cell_file = argv[++i];
    else if (a == "--poses" && i + 1 < argc) n = std::atoi(argv[++i]);
    else if (a == "--seed" && i + 1 < argc) seed = static_cast<unsigned>(std::atoi(argv[++i]));
    else {
      std::fprintf(stderr, "usage: bench_ik [--cell FILE] [--poses N] [--seed S]\n");
      return 2;
    }
  }
  if (n <= 0) {
    std::fprintf(stderr, "bench_ik: --poses must be a positive count, got %d\n", n);
    return 2;
  }
  sp::CellModel closed = sp::load_cell(cell_file);
  if (closed.kinematics != sp::CellKinematics::arm_turntable || !closed.arm_ik_closed_form()) {
    std::fprintf(stderr, "bench_ik: %s is not an arm with the Universal Robots geometry (arm.ik would not be closed form)\n",
                 cell_file.c_str());
    return 2;
  }
  closed.arm_ik = sp::ArmIkSolver::closed_form;
  sp::CellModel numerical = closed;
  numerical.arm_ik = sp::ArmIkSolver::numerical;
  const auto poses = sp::view_like_poses(n, seed);
  const Run c = solve_all(closed, poses), m = solve_all(numerical, poses);
  int both = 0, only_closed = 0, only_numerical = 0, solved_c = 0, solved_m = 0;
  for (int i = 0; i < n; ++i) {
    solved_c += c.solved[i];
    solved_m += m.solved[i];
    both += c.solved[i] && m.solved[i];
    only_closed += c.solved[i] && !m.solved[i];
    only_numerical += !c.solved[i] && m.solved[i];
  }
  std::printf("cell %s, %d planner-like poses (seed %u), one thread\n", closed.name.c_str(), n, seed);
  std::printf("%-12s %8s %12s %10s %14s\n", "solver", "solved", "solves_per_s", "total_s", "worst_err");
  std::printf("%-12s %8d %12.0f %10.3f %14.2e\n", "closed_form", solved_c, n / c.seconds, c.seconds, c.worst_error);
  std::printf("%-12s %8d %12.0f %10.3f %14.2e\n", "numerical", solved_m, n / m.seconds, m.seconds, m.worst_error);
  std::printf("numerical / closed_form time: %.1f\n", m.seconds / c.seconds);
  std::printf("solved by both %d, only closed_form %d, only numerical %d\n", both, only_closed, only_numerical);
  return only_numerical == 0 ? 0 : 1;
}

int main(int argc, char** argv) {
  return scancell::bench::guarded("bench_ik", [&] { return run_bench(argc, argv); });
}
