// Point-to-plane ICP of an executed view against the model: a known perturbation is undone, a featureless
// view is flagged instead of drifting, a view off the model is refused.
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "planner/config.hpp"
#include "planner/reconstruction/registration.hpp"
#include "planner/sim/virtual_scanner.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

using ::testing::HasSubstr;
using testing::kDeg;

/// The image of a view from `from` looking at `at` (object frame), scan length 80 mm, with sensor noise.
RangeImage scan_image(const TriangleMesh& m, const Eigen::Vector3d& at, const Eigen::Vector3d& from) {
  const SensorModel s = load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml"));
  const Eigen::Vector3d z = (from - at).normalized();
  // Baseline horizontal, as the cell keeps it.
  const Eigen::Vector3d y = std::abs(z.z()) > 0.99 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ().cross(z).normalized();
  const Eigen::Vector3d x = y.cross(z);
  ScanPose pose;
  pose.camera_to_object.linear() << x, y, z;
  pose.camera_to_object.translation() = from;
  pose.scan_length_mm = 80.0;
  return virtual_scan(OcclusionScene(m), s, pose);
}

std::vector<Eigen::Vector3d> scan(const TriangleMesh& m, const Eigen::Vector3d& at, const Eigen::Vector3d& from) {
  const RangeImage img = scan_image(m, at, from);
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
  EXPECT_GT(r.conditioning, 3 * IcpOptions{}.min_conditioning);
}

/// A turn the positioner cannot make is refused, not applied: the same corner turned 5° about its own middle
/// (samples move at most 4.4 mm, inside the pairing distance) registers back to within 0.05° unbounded, and
/// with IcpOptions::max_turn_rad 2° the fit is refused, naming the turn it found.
TEST(Registration, ATurnBeyondWhatThePositionerCanErrIsRefused) {
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  const auto pts = scan(cube, {50, 50, 50}, Eigen::Vector3d(50, 50, 50) + 200.0 * Eigen::Vector3d(1, 1, 1).normalized());
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : pts) centroid += p / static_cast<double>(pts.size());
  Eigen::Isometry3d err = Eigen::Isometry3d::Identity();
  err.translate(centroid).rotate(Eigen::AngleAxisd(5.0 * kDeg, Eigen::Vector3d(1, -1, 0).normalized())).translate(-centroid);
  std::vector<Eigen::Vector3d> seen;
  double farthest = 0.0;
  for (const auto& p : pts) {
    seen.push_back(err * p);
    farthest = std::max(farthest, (seen.back() - p).norm());
  }
  ASSERT_LT(farthest, IcpOptions{}.max_distance_mm);
  const IcpResult free = register_points(seen, model);
  ASSERT_TRUE(free.ok) << free.why;
  EXPECT_LT(Eigen::AngleAxisd((free.correction * err).linear()).angle(), 0.05 * kDeg);
  IcpOptions bounded;
  bounded.max_turn_rad = 2.0 * kDeg;
  const IcpResult r = register_points(seen, model, bounded);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("turns the view 5.0°, beyond the pose error bound of 2.0°"));
}

/// Plate motions only (a part resting on a plate, issue 20): a turn about the table axis and a shift on the
/// plate are undone; a tilt and a lift the points also carry are left exactly as they were (the plate fixes
/// them, so the fit must not trade them against noise); pivots are refused.
TEST(Registration, PlateMotionsUndoATurnAndShiftAndLeaveTiltAndHeight) {
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  const auto pts = scan(cube, {50, 50, 50}, Eigen::Vector3d(50, 50, 50) + 200.0 * Eigen::Vector3d(1, 1, 1).normalized());
  const Eigen::Vector3d axis_point(20, 10, 0), up = Eigen::Vector3d::UnitZ();
  // The operator's error: 2° about the table axis and 1.2 mm across it.
  Eigen::Isometry3d plate = Eigen::Isometry3d::Identity();
  plate.translate(axis_point).rotate(Eigen::AngleAxisd(2.0 * kDeg, up)).translate(-axis_point);
  plate.pretranslate(Eigen::Vector3d(0.9, -0.8, 0.0));
  std::vector<Eigen::Vector3d> seen;
  for (const auto& p : pts) seen.push_back(plate * p);
  IcpOptions o;
  o.plate_axis = IcpOptions::PlateAxis{axis_point, up};
  const IcpResult r = register_points(seen, model, o);
  ASSERT_TRUE(r.ok) << r.why;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : pts) centroid += p / static_cast<double>(pts.size());
  const Eigen::Isometry3d left = r.correction * plate;
  EXPECT_LT(Eigen::AngleAxisd(left.linear()).angle(), 0.02 * kDeg);
  EXPECT_LT((left * centroid - centroid).norm(), 0.02);
  // The correction itself is a plate motion: its rotation is about the axis and it moves nothing along it.
  EXPECT_NEAR(std::abs(Eigen::AngleAxisd(r.correction.linear()).axis().dot(up)), 1.0, 1e-9);
  EXPECT_NEAR((r.correction * centroid - centroid).dot(up), 0.0, 1e-9);

  // Tilted by 0.5° about x and lifted 0.3 mm as well: only the turn and the shift are undone.
  Eigen::Isometry3d tilt = Eigen::Isometry3d::Identity();
  tilt.rotate(Eigen::AngleAxisd(0.5 * kDeg, Eigen::Vector3d::UnitX())).pretranslate(Eigen::Vector3d(0, 0, 0.3));
  seen.clear();
  for (const auto& p : pts) seen.push_back(plate * tilt * p);
  const IcpResult t = register_points(seen, model, o);
  ASSERT_TRUE(t.ok) << t.why;
  EXPECT_NEAR(std::abs(Eigen::AngleAxisd(t.correction.linear()).axis().dot(up)), 1.0, 1e-9);
  EXPECT_NEAR((t.correction * centroid - centroid).dot(up), 0.0, 1e-9);
  const IcpResult free6 = register_points(seen, model);  // all six: the tilt and lift go too
  ASSERT_TRUE(free6.ok) << free6.why;
  EXPECT_LT(Eigen::AngleAxisd((free6.correction * plate * tilt).linear()).angle(), 0.05 * kDeg);

  EXPECT_THROW(register_points(seen, model, o, seen), std::invalid_argument);
}

TEST(Registration, UndoesACameraOrientationErrorThatShearsALineScan) {
  // The sweep axis carries every profile along the same line; a camera tilted by 1° turns each profile about
  // its own laser origin, so over the 80 mm sweep the image is sheared by ±0.7 mm, which no rigid motion
  // matches. Registration about the profiles' pivots undoes it; a rigid registration leaves the shear.
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  const RangeImage truth = scan_image(cube, {50, 50, 50}, Eigen::Vector3d(50, 50, 50) + 200.0 * Eigen::Vector3d(1, 1, 1).normalized());
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(1.0 * kDeg, Eigen::Vector3d(0.2, 1, -0.4).normalized()).toRotationMatrix();
  const Eigen::Vector3d shift(0.6, -0.5, 0.62);
  // What the cell stored: each sample where the modelled pose put it, i.e. the truth moved back by the error.
  RangeImage seen = truth;
  for (auto& smp : seen.samples)
    if (smp.valid()) {
      const Eigen::Vector3d o = seen.pose.camera_to_object * Eigen::Vector3d(0, smp.camera_mm.y(), 0);
      smp.object_mm = (tilt.transpose() * (smp.object_mm.cast<double>() - o - shift) + o).cast<float>();
    }
  std::vector<Eigen::Vector3d> pts;
  for (const auto& smp : seen.samples)
    if (smp.valid()) pts.push_back(smp.object_mm.cast<double>());
  auto worst_error = [&](const RangeImage& img) {
    double worst = 0.0;
    for (std::size_t k = 0; k < img.samples.size(); ++k)
      if (img.samples[k].valid()) worst = std::max(worst, (img.samples[k].object_mm - truth.samples[k].object_mm).cast<double>().norm());
    return worst;
  };
  EXPECT_GT(worst_error(seen), 1.0);
  const IcpResult r = register_scan(scan_samples(seen), model);
  ASSERT_TRUE(r.ok) << r.why;
  RangeImage fixed = seen;
  apply_correction(fixed, r.correction);
  EXPECT_LT(worst_error(fixed), 0.05);
  // The pose moved back to where the camera really was.
  EXPECT_LT(Eigen::AngleAxisd(fixed.pose.camera_to_object.linear() * truth.pose.camera_to_object.linear().transpose() * tilt.transpose()).angle(), 0.05 * kDeg);
  EXPECT_LT((fixed.pose.camera_to_object.translation() - truth.pose.camera_to_object.translation() - shift).norm(), 0.1);
  // The pose moved with the mid-sweep profile, and samples are still where the pose says (acquisition's rule).
  for (std::size_t k = 0; k < fixed.samples.size(); k += 97) {
    if (fixed.samples[k].valid()) {
      EXPECT_LT((fixed.pose.camera_to_object * fixed.samples[k].camera_mm.cast<double>() - fixed.samples[k].object_mm.cast<double>()).norm(), 1e-3);
    }
  }
  const IcpResult rigid = register_points(pts, model);
  ASSERT_TRUE(rigid.ok) << rigid.why;
  RangeImage rigid_fixed = seen;
  rigid_fixed.kind = SensorKind::random_access;  // pivot at the camera: a rigid motion
  apply_correction(rigid_fixed, rigid.correction);
  EXPECT_GT(worst_error(rigid_fixed), 0.2);
}

TEST(Registration, TheModelOfACoarseMeshFollowsTheSurfaceNotItsChords) {
  // A sphere of radius 40 mm with 10 mm edges: its flat triangles lie up to e²/8R ≈ 0.3 mm inside the
  // sphere, and ICP against them would pull each view that far along its rays. The PN patches through the
  // vertices stay within 0.05 mm of the sphere, with normals within 2° of the radius.
  const double r = 40.0;
  const TriangleMesh coarse = testing::uv_sphere({0, 0, 0}, r, 12, 24);
  const ModelCloud model = ModelCloud::from_mesh(coarse, 1.0);
  ASSERT_GT(model.size(), 5000u);
  double worst = 0.0, mean = 0.0, worst_angle = 0.0;
  for (std::size_t i = 0; i < model.size(); ++i) {
    const Eigen::Vector3d& p = model.point(i);
    // Away from the poles, where the uv sphere's triangles fan into a crease-like cone.
    if (std::abs(p.z()) > 0.85 * r) continue;
    worst = std::max(worst, std::abs(p.norm() - r));
    mean += (p.norm() - r) / static_cast<double>(model.size());
    worst_angle = std::max(worst_angle, std::acos(std::clamp(model.normal(i).dot(p.normalized()), -1.0, 1.0)));
  }
  EXPECT_LT(worst, 0.05);
  EXPECT_LT(std::abs(mean), 0.01);
  EXPECT_LT(worst_angle, 2.0 * kDeg);
}

TEST(Registration, AFeaturelessPlaneIsIllConditionedNotDrifting) {
  const TriangleMesh plane = testing::flat_patch(300.0, 5.0);
  const ModelCloud model = ModelCloud::from_mesh(plane, 1.0);
  std::vector<Eigen::Vector3d> pts = scan(plane, {0, 0, 0}, {0, 0, 200});
  for (auto& p : pts) p += Eigen::Vector3d(0.7, 0.7, 0.3);
  const IcpResult r = register_points(pts, model);
  EXPECT_FALSE(r.ok);
  EXPECT_THAT(r.why, HasSubstr("ill-conditioned"));
  EXPECT_LT(r.conditioning, IcpOptions{}.min_conditioning);
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

TEST(Registration, PartialRegistrationOfAFaceSeenAloneMovesItOnlyAcrossTheFace) {
  // The cube's top face alone, off by (0.7, 0.7, 0.3) mm: its shape fixes the height, not where along itself
  // it lies. In partial mode the height is corrected and the slides are left as positioned and counted —
  // the samples near the face's edge must not pair with the side faces and invent a constraint.
  const TriangleMesh cube = load_mesh(testing::source_path("tests/data/cube50.off"));
  const ModelCloud model = ModelCloud::from_mesh(cube, 1.0);
  RangeImage img = scan_image(cube, {25, 25, 50}, Eigen::Vector3d(25, 25, 50) + 200.0 * Eigen::Vector3d(-0.3, -0.3, 1).normalized());
  const Eigen::Vector3d off(0.7, 0.7, 0.3);
  for (auto& s : img.samples)
    if (s.valid()) {
      if (s.object_mm.z() < 49.9) s.measured = false;
      else s.object_mm += off.cast<float>();
    }
  IcpOptions o;
  o.partial = true;
  const ScanSamples samples = scan_samples(img);
  const IcpResult r = register_scan(samples, model, o);
  ASSERT_TRUE(r.ok) << r.why;
  EXPECT_GE(r.free_directions, 3);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < samples.points.size(); ++i) {
    const Eigen::Vector3d& p = samples.points[i];
    mean += (r.correction.linear() * (p - samples.pivots[i]) + samples.pivots[i] + r.correction.translation() - p) / static_cast<double>(samples.points.size());
  }
  EXPECT_NEAR(mean.z(), -0.3, 0.02);
  EXPECT_LT(std::hypot(mean.x(), mean.y()), 0.05) << mean.transpose();
}

/// A face seen with a band of its side, registered to a model that is off by a voxel (a fused rough model:
/// the side stands 1.5 mm out). The band is 4.7 % of the samples, so it holds the slide across the side
/// with λ ≈ 0.047: over the default 0.01, the model's error drags the whole view 1.5 mm; for_model_error's
/// (1.5 / 5)² = 0.09 leaves that slide as positioned and corrects what the face fixes firmly, its height.
TEST(Registration, AModelOffByAVoxelDoesNotDragAFaceOnViewSideways) {
  TriangleMesh coarse = load_mesh(testing::source_path("tests/data/cube50.off"));
  for (auto& v : coarse.vertices)
    if (v.x() < 1e-9) v.x() = -1.5;
  const ModelCloud model = ModelCloud::from_mesh(coarse, 0.5);
  std::vector<Eigen::Vector3d> pts, normals;
  for (int a = 0; a <= 80; ++a)
    for (int b = 0; b <= 80; ++b) {
      pts.emplace_back(5.0 + 0.5 * a, 5.0 + 0.5 * b, 50.3);  // the top, 0.3 mm high
      normals.emplace_back(0, 0, 1);
    }
  for (int a = 0; a <= 80; ++a)
    for (int c = 0; c < 4; ++c) {
      pts.emplace_back(0.0, 5.0 + 0.5 * a, 40.3 + 0.5 * c);  // the band of the side x = 0
      normals.emplace_back(-1, 0, 0);
    }
  const double share = 324.0 / static_cast<double>(pts.size());
  ASSERT_NEAR(share, 0.047, 0.001);
  const auto mean_motion = [&](const IcpResult& r) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pts) mean += (r.correction * p - p) / static_cast<double>(pts.size());
    return mean;
  };
  IcpOptions o;
  o.partial = true;
  const IcpResult loose = register_points(pts, model, o, {}, normals);
  ASSERT_TRUE(loose.ok) << loose.why;
  EXPECT_NEAR(mean_motion(loose).x(), -1.5, 0.1);  // dragged by the model's error
  const IcpOptions strict = for_model_error(o, 1.5);
  EXPECT_NEAR(strict.min_conditioning, 0.09, 1e-12);  // (1.5 mm / 5 mm)²
  const IcpResult r = register_points(pts, model, strict, {}, normals);
  ASSERT_TRUE(r.ok) << r.why;
  // Free: the slide along the band; and now the slide across the side and the turn about the top's normal,
  // which only the band held.
  EXPECT_EQ(loose.free_directions, 1);
  EXPECT_EQ(r.free_directions, 3);
  const Eigen::Vector3d m = mean_motion(r);
  EXPECT_NEAR(m.z(), -0.3, 0.02);
  EXPECT_LT(std::hypot(m.x(), m.y()), 0.05) << m.transpose();
  // A model error in the registration's own units: none keeps the options, a negative one is refused.
  EXPECT_DOUBLE_EQ(for_model_error(o, 0.0).min_conditioning, o.min_conditioning);
  EXPECT_THROW(for_model_error(o, -1.0), std::invalid_argument);
}

}  // namespace
}  // namespace scancell::planner
