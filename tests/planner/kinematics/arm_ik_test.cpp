// The closed-form inverse kinematics of the Universal Robots geometry (planner/kinematics/arm_ik.hpp), checked
// against the cell's own forward kinematics (KDL's chain) and a hand-computed pose.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/errors.hpp"

#include "planner/kinematics/arm_ik.hpp"
#include "planner/kinematics/cell.hpp"
#include "test_meshes.hpp"

namespace sp = scancell::planner;

namespace {

sp::CellModel arm_cell() { return sp::load_cell(sp::testing::source_path("config/cells/arm-turntable.yaml")); }

double pose_distance(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return std::max((a.translation() - b.translation()).norm(), Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle());
}

/// The flange in the arm's base frame at arm joints `q`, the turntable at 0, by the cell's forward kinematics
/// (KDL's chain, not arm_ik's DH product).
Eigen::Isometry3d flange_by_cell(const sp::CellModel& c, const std::array<double, 6>& q) {
  sp::JointVector j{0.0};
  j.insert(j.end(), q.begin(), q.end());
  return c.arm_base.inverse() * sp::table_to_world(c, 0.0) * c.object_on_table * sp::forward_kinematics(c, j) * c.tool.inverse();
}

double angle_gap(double a, double b) { return std::abs(std::remainder(a - b, 2.0 * M_PI)); }

}  // namespace

TEST(ArmIk, TheShippedArmHasTheUniversalRobotsGeometryAndOthersAreRefused) {
  const auto c = arm_cell();
  EXPECT_TRUE(sp::has_ur_geometry(c.dh));
  auto bent = c.dh;
  bent[3][0] = 5.0;  // an offset a4 breaks the parallel-axes decoupling
  EXPECT_FALSE(sp::has_ur_geometry(bent));
  bent = c.dh;
  bent[4][1] = 1.5707963267949;  // a wrist twisted the other way
  EXPECT_FALSE(sp::has_ur_geometry(bent));
  EXPECT_FALSE(sp::has_ur_geometry(sp::ArmDh(c.dh.begin(), c.dh.begin() + 5)));
}

TEST(ArmIk, AtZeroTheFlangeStandsWhereTheLinkLengthsPutItAndIsSolvedBack) {
  // UR geometry, all joints at zero: the arm lies stretched along base x (a2 + a3), the wrist offsets d4 and
  // d6 point along -y and d5 down, so the flange is at (a2 + a3, -(d4 + d6), d1 - d5) looking along -y.
  const auto dh = arm_cell().dh;
  const Eigen::Isometry3d zero = sp::dh_forward_kinematics(dh, {0, 0, 0, 0, 0, 0});
  EXPECT_NEAR(zero.translation().x(), -612.0 - 572.3, 1e-9);
  EXPECT_NEAR(zero.translation().y(), -(163.9 + 92.2), 1e-9);
  EXPECT_NEAR(zero.translation().z(), 127.3 - 115.7, 1e-9);
  EXPECT_LT((zero.linear().col(2) - Eigen::Vector3d(0, -1, 0)).norm(), 1e-12);
  // theta5 = 0 is the wrist singularity (z6 parallel to the shoulder axis): only theta4 + theta6 is determined,
  // so theta6 is taken as given and the zero pose comes back (to the ~1e-8 rad acos leaves near ±1).
  bool found = false;
  for (const auto& q : sp::ur_inverse_kinematics(dh, zero, 0.0)) {
    EXPECT_LT(pose_distance(sp::dh_forward_kinematics(dh, q), zero), 1e-9);
    bool same = true;
    for (int k = 0; k < 6; ++k) same = same && angle_gap(q[k], 0.0) < 1e-6;
    found = found || same;
  }
  EXPECT_TRUE(found);
}

TEST(ArmIk, EveryBranchReproducesThePoseAndOneIsTheJointsItCameFrom) {
  const auto c = arm_cell();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  int branches = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::array<double, 6> q;
    for (double& v : q) v = angle(rng);
    const Eigen::Isometry3d flange = flange_by_cell(c, q);
    const auto solutions = sp::ur_inverse_kinematics(c.dh, flange);
    branches += static_cast<int>(solutions.size());
    double nearest = 1e9;
    for (const auto& s : solutions) {
      EXPECT_LT(pose_distance(flange_by_cell(c, s), flange), 1e-6) << "trial " << trial;
      double gap = 0.0;
      for (int k = 0; k < 6; ++k) gap = std::max(gap, angle_gap(s[k], q[k]));
      nearest = std::min(nearest, gap);
    }
    EXPECT_LT(nearest, 1e-6) << "trial " << trial << ": the joints the pose came from are not among "
                             << solutions.size() << " solutions";
  }
  // Up to 8 branches (shoulder, wrist, elbow) per pose; a shoulder or wrist branch whose wrist centre the
  // elbow cannot reach drops out. A numerical solver from one seed finds one.
  EXPECT_GT(branches, 5 * 200);
}

TEST(ArmIk, TheCellTakesTheBranchNearestItsSeed) {
  // Elbow down at the home view: the same camera pose, another branch. Seeded there, the cell's inverse
  // kinematics stays there; seeded at home, it returns home. (To 1e-3 rad: the cell sets the turntable by its
  // own rule, 2e-5 rad off the home's, and the arm follows; branches differ by tenths of a radian.)
  const auto c = arm_cell();
  const sp::JointVector home = c.home();
  const Eigen::Isometry3d pose = sp::forward_kinematics(c, home);
  std::array<double, 6> h;
  for (int k = 0; k < 6; ++k) h[k] = home[1 + k];
  const Eigen::Isometry3d flange = flange_by_cell(c, h);
  sp::JointVector other;
  for (const auto& s : sp::ur_inverse_kinematics(c.dh, flange)) {
    if (angle_gap(s[2], h[2]) < 0.1) continue;  // the same elbow
    other = {home[0]};
    for (int k = 0; k < 6; ++k) other.push_back(std::remainder(s[k] - h[k], 2.0 * M_PI) + h[k]);
    bool inside = true;
    for (std::size_t k = 0; k < other.size(); ++k) inside = inside && other[k] >= c.axes[k].min && other[k] <= c.axes[k].max;
    if (inside) break;
    other.clear();
  }
  ASSERT_FALSE(other.empty());
  const auto from_home = sp::inverse_kinematics(c, pose, 40.0);
  ASSERT_TRUE(from_home.ok) << from_home.why;
  for (std::size_t k = 0; k < home.size(); ++k) EXPECT_NEAR(from_home.q[k], home[k], 1e-3) << "axis " << k;
  const auto from_other = sp::inverse_kinematics(c, pose, 40.0, &other);
  ASSERT_TRUE(from_other.ok) << from_other.why;
  for (std::size_t k = 0; k < other.size(); ++k) EXPECT_NEAR(from_other.q[k], other[k], 1e-3) << "axis " << k;
}

TEST(ArmIk, TheSolverIsChosenInTheCellFileAndClosedFormNeedsItsGeometry) {
  const auto dir = std::filesystem::temp_directory_path() / "scancell_arm_ik_test";
  std::filesystem::create_directories(dir);
  std::ifstream in(sp::testing::source_path("config/cells/arm-turntable.yaml"));
  const std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto with_ik = [&](const std::string& value, bool offset_wrist) {
    std::string t = good;
    const std::string shipped = "ik: automatic";
    t.replace(t.find(shipped), shipped.size(), "ik: " + value);
    const std::string wrist = "[0, 1.5707963267949, 163.9, 0]";  // a4 = 0
    if (offset_wrist) t.replace(t.find(wrist), wrist.size(), "[5, 1.5707963267949, 163.9, 0]");
    std::ofstream(dir / "c.yaml") << t;
    return sp::load_cell(dir / "c.yaml");
  };
  EXPECT_TRUE(arm_cell().arm_ik_closed_form());  // automatic, on the UR geometry
  EXPECT_FALSE(with_ik("numerical", false).arm_ik_closed_form());
  EXPECT_FALSE(with_ik("automatic", true).arm_ik_closed_form());
  EXPECT_THAT([&] { with_ik("closed_form", true); },
              ::testing::ThrowsMessage<scancell::ConfigError>(::testing::HasSubstr("arm.ik: closed_form needs the Universal Robots geometry")));
  EXPECT_THAT([&] { with_ik("analytic", false); },
              ::testing::ThrowsMessage<scancell::ConfigError>(::testing::HasSubstr("arm.ik: must be automatic, closed_form or numerical, got 'analytic'")));
  // Both solvers put the camera where it was asked, within the limits; on the home view they agree.
  const auto numerical = with_ik("numerical", false);
  const Eigen::Isometry3d pose = sp::forward_kinematics(numerical, numerical.home());
  const auto a = sp::inverse_kinematics(numerical, pose, 40.0), b = sp::inverse_kinematics(arm_cell(), pose, 40.0);
  ASSERT_TRUE(a.ok && b.ok) << a.why << b.why;
  for (std::size_t k = 0; k < a.q.size(); ++k) EXPECT_NEAR(a.q[k], b.q[k], 1e-6) << "axis " << k;
  std::filesystem::remove_all(dir);
}
