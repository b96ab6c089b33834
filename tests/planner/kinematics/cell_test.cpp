// Cell kinematics (both shipped cells), reachability, move times, travel order, collisions, and the
// thesis' analytic pose-error tables and Monte Carlo.
#include <cmath>
#include <fstream>
#include <random>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "planner/kinematics/cell.hpp"
#include "common/errors.hpp"
#include "planner/plan.hpp"
#include "planner/kinematics/pose_error.hpp"
#include "planner/sim/synthetic.hpp"
#include "planner/sim/verify.hpp"
#include "test_meshes.hpp"

namespace sp = scancell::planner;
using ::testing::HasSubstr;

namespace {

sp::CellModel cell(const std::string& name) { return sp::load_cell(sp::testing::source_path("config/cells/" + name + ".yaml")); }

double pose_distance(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return std::max((a.translation() - b.translation()).norm(), Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle());
}

/// Random axis positions inside the limits (a sub-range `frac` of each around home).
sp::JointVector random_q(const sp::CellModel& c, std::mt19937& rng, double frac) {
  sp::JointVector q;
  for (const auto& a : c.axes) {
    const double lo = std::max(a.min, a.home - frac * (a.max - a.min) / 2), hi = std::min(a.max, a.home + frac * (a.max - a.min) / 2);
    q.push_back(std::uniform_real_distribution<double>(lo, hi)(rng));
  }
  return q;
}

}  // namespace

TEST(Cell, TurntableLiftTiltInverseKinematicsRoundTrips) {
  const auto c = cell("turntable-lift-tilt");
  ASSERT_EQ(c.axes.size(), 5u);
  std::mt19937 rng(3);
  int solved = 0;
  for (int k = 0; k < 200; ++k) {
    sp::JointVector q = random_q(c, rng, 0.8);
    const Eigen::Isometry3d pose = sp::forward_kinematics(c, q);
    const auto ik = sp::inverse_kinematics(c, pose, 40.0, &q);
    if (!ik.ok) continue;  // the sweep may sit too near its end for a 40 mm scan
    ++solved;
    EXPECT_LT(pose_distance(sp::forward_kinematics(c, ik.q), pose), 1e-9);
    for (std::size_t a = 0; a < c.axes.size(); ++a) {
      EXPECT_GE(ik.q[a], c.axes[a].min - 1e-9);
      EXPECT_LE(ik.q[a], c.axes[a].max + 1e-9);
    }
  }
  EXPECT_GT(solved, 150);
}

TEST(Cell, ArmTurntableInverseKinematicsRoundTrips) {
  // Views as the planner makes them: 200-400 mm from the object's centre, from any azimuth (the turntable
  // brings them to the arm), elevations from -10° to 75°, any twist.
  const auto c = cell("arm-turntable");
  ASSERT_EQ(c.axes.size(), 7u);
  int solved = 0;
  for (const Eigen::Isometry3d& pose : sp::view_like_poses(60, 4)) {
    const auto ik = sp::inverse_kinematics(c, pose, 40.0);
    if (!ik.ok) continue;
    ++solved;
    EXPECT_LT(pose_distance(sp::forward_kinematics(c, ik.q), pose), 1e-9);
    for (std::size_t j = 0; j < c.axes.size(); ++j) {
      EXPECT_GE(ik.q[j], c.axes[j].min - 1e-9);
      EXPECT_LE(ik.q[j], c.axes[j].max + 1e-9);
    }
  }
  EXPECT_GE(solved, 50);
  // And from joint space: forward, then back.
  const auto home_pose = sp::forward_kinematics(c, c.home());
  const auto back = sp::inverse_kinematics(c, home_pose, 40.0);
  ASSERT_TRUE(back.ok) << back.why;
  EXPECT_LT(pose_distance(sp::forward_kinematics(c, back.q), home_pose), 1e-9);
}

TEST(Cell, UnreachablePosesAreReportedWithTheReason) {
  const auto tt = cell("turntable-lift-tilt");
  Eigen::Isometry3d far = sp::forward_kinematics(tt, tt.home());
  far.translation() += Eigen::Vector3d(0, 0, 5000);
  auto r = sp::inverse_kinematics(tt, far, 40.0);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("lift"));
  // A camera whose baseline is not horizontal cannot be reached as such; the nearest reachable pose keeps the
  // boresight and the position and turns the view about its boresight.
  Eigen::Isometry3d tilted = sp::forward_kinematics(tt, tt.home());
  tilted.linear() = tilted.linear() * Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  r = sp::inverse_kinematics(tt, tilted, 40.0);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("baseline"));
  sp::JointVector q;
  const auto near = sp::nearest_reachable(tt, tilted, 40.0, &q);
  ASSERT_TRUE(near.has_value());
  EXPECT_LT((near->translation() - tilted.translation()).norm(), 1e-9);
  EXPECT_LT((near->linear().col(2) - tilted.linear().col(2)).norm(), 1e-9);
  EXPECT_NEAR(Eigen::AngleAxisd(near->linear().transpose() * tilted.linear()).angle(), 0.4, 1e-9);
  EXPECT_LT(pose_distance(sp::forward_kinematics(tt, q), *near), 1e-9);
  const auto arm = cell("arm-turntable");
  Eigen::Isometry3d out_of_reach = Eigen::Isometry3d::Identity();
  out_of_reach.translation() = Eigen::Vector3d(0, 0, 4000);
  r = sp::inverse_kinematics(arm, out_of_reach, 40.0);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("arm"));
}

TEST(Cell, MoveTimesFollowTheTrapezoidalProfile) {
  sp::Axis a;
  a.max_speed = 100.0;  // mm/s
  a.max_accel = 500.0;  // mm/s²: full speed after 0.2 s and 10 mm, so 20 mm to speed up and stop
  EXPECT_DOUBLE_EQ(sp::axis_move_time_s(a, 100.0), 100.0 / 100.0 + 100.0 / 500.0);  // 1.2 s
  EXPECT_DOUBLE_EQ(sp::axis_move_time_s(a, -10.0), 2.0 * std::sqrt(10.0 / 500.0));   // triangular: 0.283 s
  EXPECT_DOUBLE_EQ(sp::axis_move_time_s(a, 20.0), 0.4);                             // the two meet at 20 mm
  const auto c = cell("turntable-lift-tilt");
  sp::JointVector from = c.home(), to = c.home();
  to[1] += 100.0;  // reach: 200 mm/s, 800 mm/s² -> 0.5 + 0.25 s
  to[0] += 0.1;    // turntable: triangular 2·sqrt(0.1/2) = 0.447 s
  EXPECT_DOUBLE_EQ(sp::move_time_s(c, from, to), 0.75);
  EXPECT_DOUBLE_EQ(sp::scan_time_s(c, 100.0), 2.0);
}

TEST(Cell, TravelOrderVisitsAlongTheShortestTour) {
  const auto c = cell("turntable-lift-tilt");
  std::vector<sp::JointVector> targets;
  for (double reach : {600.0, 200.0, 400.0, 300.0, 500.0}) {
    sp::JointVector q = c.home();
    q[1] = reach;
    targets.push_back(q);
  }
  sp::JointVector start = c.home();
  start[1] = 150.0;
  const auto order = sp::travel_order(c, targets, start);
  EXPECT_EQ(order, (std::vector<std::size_t>{1, 3, 2, 4, 0}));  // 200, 300, 400, 500, 600
}

TEST(Cell, TheTourSolvesEachViewFromTheOneBefore) {
  // Two views the table serves at +3.0 and -3.0 rad (the other axes at home). Solved from home (table 0) the
  // second is -3.0, 6 rad from the first; solved from the first it is -3.0 + 2π = 3.2832, 0.2832 rad on.
  // Table 1 rad/s, 2 rad/s² (0.5 rad to full speed and back): 3 rad takes 3/1 + 1/2 = 3.5 s, 6 rad 6.5 s,
  // 0.2832 rad (triangular) 2·sqrt(0.2832/2) = 0.7526 s.
  const auto c = cell("turntable-lift-tilt");
  std::vector<Eigen::Isometry3d> poses;
  std::vector<sp::JointVector> from_home;
  for (double table : {3.0, -3.0}) {
    sp::JointVector q = c.home();
    q[0] = table;
    poses.push_back(sp::forward_kinematics(c, q));
    const auto ik = sp::inverse_kinematics(c, poses.back(), 40.0);
    ASSERT_TRUE(ik.ok) << ik.why;
    from_home.push_back(ik.q);
  }
  EXPECT_NEAR(from_home[1][0], -3.0, 1e-9);
  const auto order = sp::travel_order(c, from_home, c.home());
  EXPECT_NEAR(sp::move_time_s(c, c.home(), from_home[order[0]]) + sp::move_time_s(c, from_home[order[0]], from_home[order[1]]), 10.0, 1e-9);
  const sp::Travel t = sp::plan_travel(c, poses, {40.0, 40.0}, from_home, c.home());
  EXPECT_EQ(t.order, (std::vector<std::size_t>{0, 1}));
  EXPECT_NEAR(t.targets[1][0], -3.0 + 2.0 * M_PI, 1e-9);
  EXPECT_NEAR(t.move_s, 3.5 + 2.0 * std::sqrt((2.0 * M_PI - 6.0) / 2.0), 1e-9);
  EXPECT_LT(pose_distance(sp::forward_kinematics(c, t.targets[1]), poses[1]), 1e-9);  // the same camera pose
  EXPECT_THROW(sp::plan_travel(c, poses, {40.0}, from_home, c.home()), std::invalid_argument);
}

TEST(Cell, ScannerBodyCollisionsRespectTheClearance) {
  const auto c = cell("turntable-lift-tilt");
  const sp::TriangleMesh box = sp::box_with_blind_hole({120, 80, 60}, 30, 30, 10.0);
  const sp::CollisionChecker checker(c, box);
  // Looking down at the box top (z = 60) from 150 mm: the body (behind the camera) is far from everything.
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  // Identity rotation: camera z up, boresight (−z) down, baseline along +Y.
  pose.translation() = Eigen::Vector3d(0, -90, 210);
  EXPECT_FALSE(checker.collides(pose, 40.0));
  // 5 mm above the top: the body's front face is within the 10 mm clearance.
  pose.translation().z() = 65.0;
  EXPECT_TRUE(checker.collides(pose, 40.0));
  // The same height beside the box, clear of it: the sweep's travel matters (a 300 mm sweep reaches over it).
  pose.translation() = Eigen::Vector3d(0, -400, 65);
  EXPECT_FALSE(checker.collides(pose, 40.0));
  EXPECT_TRUE(checker.collides(pose, 700.0));
}

// The checker's own box-triangle test (separating axes) against FCL's GJK over the same BVH, at random body
// poses around and through the blind-hole box: the same answer wherever the body is not within 1 µm of touching.
TEST(Cell, ScannerBodyCollisionsAgreeWithFclGjk) {
  auto c = cell("turntable-lift-tilt");
  c.fixtures.clear();  // the object alone
  const sp::TriangleMesh box = sp::box_with_blind_hole({120, 80, 60}, 30, 30, 10.0);
  const sp::CollisionChecker checker(c, box);
  auto mesh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Vector3d> pts(box.vertices.begin(), box.vertices.end());
  std::vector<fcl::Triangle> tris;
  for (const auto& t : box.triangles) tris.emplace_back(t[0], t[1], t[2]);
  mesh->beginModel();
  mesh->addSubModel(pts, tris);
  mesh->endModel();
  const fcl::CollisionObjectd object(mesh, fcl::Transform3d::Identity());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int hits = 0, misses = 0, near = 0;
  for (int i = 0; i < 3000; ++i) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    pose.translation() = Eigen::Vector3d(160 * u(rng), 160 * u(rng), 30 + 150 * u(rng));
    const double scan = 100.0 + 100.0 * u(rng);
    Eigen::Vector3d lo = c.scanner_body.min.array() - c.clearance_mm, hi = c.scanner_body.max.array() + c.clearance_mm;
    lo.y() -= 0.5 * scan;
    hi.y() += 0.5 * scan;
    fcl::Transform3d tf = fcl::Transform3d::Identity();
    tf.linear() = pose.linear();
    tf.translation() = pose * (0.5 * (lo + hi));
    const fcl::CollisionObjectd body(std::make_shared<fcl::Boxd>(hi - lo), tf);
    fcl::CollisionResultd res;
    fcl::collide(&body, &object, fcl::CollisionRequestd(), res);
    const bool ours = checker.collides(pose, scan);
    if (ours != res.isCollision()) {
      fcl::DistanceResultd d;
      fcl::DistanceRequestd dreq;
      fcl::distance(&body, &object, dreq, d);
      near += std::abs(d.min_distance) < 1e-3;
      if (!(std::abs(d.min_distance) < 1e-3)) ADD_FAILURE() << "pose " << i << ": ours " << ours << ", FCL " << res.isCollision();
    }
    (ours ? hits : misses) += 1;
  }
  EXPECT_GT(hits, 1000);  // both answers are common (1,401 and 1,599; without the nine edge axes 10 poses differ)
  EXPECT_GT(misses, 1000);
  EXPECT_LE(near, 3);
}

TEST(Cell, BadCellConfigsNameTheKey) {
  const auto dir = std::filesystem::temp_directory_path() / "scancell_cell_test";
  std::filesystem::create_directories(dir);
  std::ifstream in(sp::testing::source_path("config/cells/turntable-lift-tilt.yaml"));
  const std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto refused = [&](std::string text, const std::string& expect) {
    std::ofstream(dir / "c.yaml") << text;
    try {
      sp::load_cell(dir / "c.yaml");
      ADD_FAILURE() << "accepted: " << expect;
    } catch (const scancell::ConfigError& e) {
      EXPECT_THAT(e.what(), HasSubstr(expect));
    }
  };
  std::string t = good;
  t.replace(t.find("  sweep:"), 7, "  swoop:");
  refused(t, "axes.sweep: missing");
  t = good;
  t.replace(t.find("type: linear"), 12, "type: linaer");
  refused(t, "axes.reach.type: must be rotary or linear");
  t = good;
  t.replace(t.find("min_mm: 100"), 11, "min_mm: 900");
  refused(t, "axes.reach.max_mm: must be greater than min_mm");
  t = good + "speed_of_light_mm_s: 3e11\n";
  refused(t, "speed_of_light_mm_s: unknown key");
  std::filesystem::remove_all(dir);
}

// ---- thesis chapter 7 ----

TEST(PoseError, AnalyticTablesMatchHandEvaluation) {
  // The thesis' sensor: Φx = 27° (0.471239 rad), R_o = 142 mm, f_d = 1.02; σ_p = 1 mm, σ_a = σ_t = 1° (0.0174533).
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::PoseErrorEffects e = sp::pose_error_effects(s, {1.0, 0.0174533, 0.0174533}, 1.02);
  // Table 7.3, position: μP = 1 + (σp/Ro)²/(3 f_d²) = 1 + 4.95933e-5/3.1212 = 1.0000158891.
  EXPECT_NEAR(e.precision_position.mean, 1.0000158891, 1e-9);
  // σP = sqrt(4/(3·1.0404)) · σp/Ro = 1.13206 · 0.00704225 = 0.00797225.
  EXPECT_NEAR(e.precision_position.sd, 0.00797225, 1e-7);
  // σD = sqrt(2/(3·1.0404)) · σp/Ro = 0.80048 · 0.00704225 = 0.00563718.
  EXPECT_NEAR(e.density_position.sd, 0.00563718, 1e-7);
  // Axis: μP = 1 − 3σa²/4 = 1 − 0.75·3.04618e-4 = 0.99977154; μD = 1 − σa²/4 = 0.99992385.
  EXPECT_NEAR(e.precision_axis.mean, 0.99977154, 1e-8);
  EXPECT_NEAR(e.density_axis.mean, 0.99992385, 1e-8);
  // Table 7.4, twist: TΦ2 = tan 13.5° = 0.240079; μTF = 1 − (Φx² + 4TΦ2²)/(8 Φx TΦ2)·sqrt(2/π)·σt + σt²/2
  //   = 1 − (0.222066 + 0.230553)/0.905095·0.797885·0.0174533 + 1.52309e-4 = 0.993188.
  EXPECT_NEAR(e.footprint_twist.mean, 0.993188, 1e-6);
  // Table 7.5, position: P = 1 − Φ(√3·0.02/0.00704225) = 1 − Φ(4.91902) = 4.35e-7.
  EXPECT_NEAR(e.dof_erosion_position, 4.35e-7, 0.05e-7);
  // Axis: P = 1 − Φ(0.02/(1.02·0.235619·0.0174533)) = 1 − Φ(4.76805) = 9.30e-7.
  EXPECT_NEAR(e.dof_erosion_axis, 9.30e-7, 0.1e-7);
  // f_d suggested for a 1e-3 risk: position 1 + 3.0902·0.00704225/√3 = 1.012564; axis 1/(1 − 3.0902·0.235619·
  // 0.0174533) = 1.012872: the larger.
  EXPECT_NEAR(e.suggested_fd, 1.012872, 1e-5);
}

TEST(PoseError, MonteCarloWithoutErrorReproducesTheDeterministicMvAndDeclinesWithError) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const sp::TriangleMesh patch = sp::convex_patch(130, 0.04, 1.5);
  // Four views that just tile the patch.
  std::vector<sp::ScanPose> views;
  for (double x : {-33.0, 33.0})
    for (double y : {-33.0, 33.0}) {
      sp::Viewpoint v;
      v.position = Eigen::Vector3d(x, y, 150.0);
      v.axis = -Eigen::Vector3d::UnitZ();
      v.scan_length_mm = 75.0;
      views.push_back(sp::scan_pose(v));
    }
  sp::VerifyOptions o;
  o.analytic = false;
  const double deterministic = sp::verify_views(patch, s, spec, views, {}, o).mv;
  const auto zero = sp::verify_monte_carlo(patch, s, spec, views, o, 3);
  for (double m : zero.mv) EXPECT_EQ(m, deterministic);
  EXPECT_EQ(zero.sd, 0.0);
  double previous = deterministic + 1e-12;
  for (double deg : {0.5, 1.5, 4.0}) {
    o.pose_error = {0.0, deg * M_PI / 180.0, 0.0};
    const auto mc = sp::verify_monte_carlo(patch, s, spec, views, o, 6);
    EXPECT_LT(mc.mean, previous) << deg << "°";
    previous = mc.mean;
  }
}

TEST(Cell, PlansForACellAreReachableOrderedAndSeeThePlate) {
  // A box on the plate of either shipped cell: its bottom face lies on the plate, so no view may claim it;
  // every view is reachable at its recorded axes (solved for the chosen views only, outside exact cover),
  // clear of the object, and the views run in an order of least travel.
  for (const char* name : {"turntable-lift-tilt", "arm-turntable"}) {
    SCOPED_TRACE(name);
    const auto c = cell(name);
    const sp::TriangleMesh box = sp::box_with_blind_hole({100, 70, 50}, 24, 20, 5.0);
    sp::RoughModelOptions rough;
    rough.target_vertices = 600;
    sp::PlannerSettings settings;
    const sp::ViewPlan plan = sp::plan_views(box, sp::testing::thesis_sensor(), sp::testing::thesis_spec(), settings, rough, 0, &c);
    ASSERT_TRUE(plan.cell.has_value());
    ASSERT_GT(plan.views.size(), 3u);
    ASSERT_EQ(plan.view_axes.size(), plan.views.size());
    EXPECT_GT(plan.cell_report.unreachable + plan.cell_report.colliding, 0u);
    const sp::CollisionChecker checker(*plan.cell, plan.rough.mesh());
    double travel = 0.0;
    sp::JointVector at = plan.cell->home();
    for (std::size_t k = 0; k < plan.views.size(); ++k) {
      Eigen::Isometry3d pose;
      pose.matrix() = plan.views[k].transform();
      EXPECT_LT(pose_distance(sp::forward_kinematics(*plan.cell, plan.view_axes[k]), pose), 1e-9) << "view " << k;
      EXPECT_FALSE(checker.collides(pose, plan.views[k].scan_length_mm)) << "view " << k;
      EXPECT_NEAR(plan.view_move_s[k], sp::move_time_s(*plan.cell, at, plan.view_axes[k]), 1e-12);
      travel += plan.view_move_s[k];
      at = plan.view_axes[k];
    }
    EXPECT_NEAR(plan.cell_report.travel_s, travel, 1e-9);
    // The bottom face (z = 0 in the box's own frame) is unmeasurable: every bottom row is reported.
    std::size_t bottom = 0, bottom_unmeasurable = 0;
    for (std::uint32_t r = 0; r < plan.rough.size(); ++r)
      if (plan.rough.points[r].z() < 1e-6 && plan.rough.normals[r].z() < -0.9) ++bottom;
    for (auto r : plan.cover.unmeasurable_rows)
      if (plan.rough.points[r].z() < 1e-6 && plan.rough.normals[r].z() < -0.9) ++bottom_unmeasurable;
    EXPECT_GT(bottom, 0u);
    EXPECT_EQ(bottom_unmeasurable, bottom);
  }
}
