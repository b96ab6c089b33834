// Point-to-plane ICP of an executed view against the model: a known perturbation is undone, a featureless
// view is flagged instead of drifting, a view off the model is refused.
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "planner/config.hpp"
#include "planner/registration.hpp"
#include "planner/virtual_scanner.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

using ::testing::HasSubstr;
constexpr double kDeg = std::numbers::pi / 180.0;

/// The samples of a view from `from` looking at `at` (object frame), scan length 80 mm, with sensor noise.
std::vector<Eigen::Vector3d> scan(const TriangleMesh& m, const Eigen::Vector3d& at, const Eigen::Vector3d& from) {
  const SensorModel s = load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml"));
  const Eigen::Vector3d z = (from - at).normalized();
  // Baseline horizontal, as the cell keeps it.
  const Eigen::Vector3d y = std::abs(z.z()) > 0.99 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ().cross(z).normalized();
  const Eigen::Vector3d x = y.cross(z);
  ScanPose pose;
  pose.camera_to_object.linear() << x, y, z;
  pose.camera_to_object.translation() = from;
  pose.scan_length_mm = 80.0;
  const RangeImage img = virtual_scan(OcclusionScene(m), s, pose);
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : img.samples)
    if (p.valid()) out.push_back(p.object_mm.cast<double>());
  return out;
}

TEST(Registration, UndoesAKnownPoseErrorOnACubeCorner) {
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  // Looking into the corner: all three faces in view, so all six degrees of freedom are fixed.
  const auto pts = scan(cube, {50, 50, 50}, Eigen::Vector3d(50, 50, 50) + 200.0 * Eigen::Vector3d(1, 1, 1).normalized());
  ASSERT_GT(pts.size(), 20000u);
  // The positioner was off by 1 mm and 1°: the samples sit where the model thought the camera was.
  Eigen::Isometry3d err = Eigen::Isometry3d::Identity();
  err.linear() = Eigen::AngleAxisd(1.0 * kDeg, Eigen::Vector3d(0.3, -1, 0.5).normalized()).toRotationMatrix();
  err.translation() = Eigen::Vector3d(0.6, -0.5, 0.62);  // |t| = 1.0 mm
  std::vector<Eigen::Vector3d> seen;
  for (const auto& p : pts) seen.push_back(err * p);
  const IcpResult r = register_points(seen, model);
  ASSERT_TRUE(r.ok) << r.why;
  const Eigen::Isometry3d left = r.correction * err;  // identity when fully undone
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : pts) centroid += p / static_cast<double>(pts.size());
  EXPECT_LT(Eigen::AngleAxisd(left.linear()).angle(), 0.05 * kDeg);
  EXPECT_LT((left * centroid - centroid).norm(), 0.05);
  EXPECT_LT(r.rms_mm, 0.05);  // the sensor noise (σz 0.02-0.03 mm here), not the pose error
  EXPECT_GT(r.overlap, 0.9);
  EXPECT_GT(r.conditioning, 1e-2);
}

TEST(Registration, AFeaturelessPlaneIsIllConditionedNotDrifting) {
  const TriangleMesh plane = testing::flat_patch(300.0, 5.0);
  const ModelCloud model = ModelCloud::from_mesh(plane, 1.0);
  std::vector<Eigen::Vector3d> pts = scan(plane, {0, 0, 0}, {0, 0, 200});
  for (auto& p : pts) p += Eigen::Vector3d(0.7, 0.7, 0.3);
  const IcpResult r = register_points(pts, model);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("ill-conditioned"));
  EXPECT_LT(r.conditioning, 1e-2);
}

TEST(Registration, AnEdgeSeenAloneSlidesAlongItselfAndIsFlagged) {
  // Two faces of the cube only: translation along their common edge is free (thesis 8.2's caveat).
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : scan(cube, {25, 50, 50}, Eigen::Vector3d(25, 50, 50) + 200.0 * Eigen::Vector3d(0, 1, 1).normalized()))
    if (p.x() > 3.0 && p.x() < 47.0) pts.push_back(p);  // away from the two end faces
  const IcpResult r = register_points(pts, model);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("ill-conditioned"));
  EXPECT_GT(std::abs(r.weakest(3)), 0.9) << r.weakest.transpose();  // the free motion: translation along x
}

TEST(Registration, AViewOffTheModelIsRefusedForLackOfOverlap) {
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  std::vector<Eigen::Vector3d> pts = scan(cube, {50, 50, 50}, Eigen::Vector3d(50, 50, 50) + 200.0 * Eigen::Vector3d(1, 1, 1).normalized());
  for (auto& p : pts) p += Eigen::Vector3d(40.0, 40.0, 40.0);
  const IcpResult r = register_points(pts, model);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("overlap"));
}

}  // namespace
}  // namespace scancell::planner
