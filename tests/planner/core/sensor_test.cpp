// Sensor performance model against values computed by hand from thesis eq. 3.3-3.8.
#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "planner/core/viewpoint.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

using testing::kDeg;

TEST(SensorModel, PrecisionAtMinimumRangeIsTenMicrons) {
  const SensorModel s = testing::thesis_sensor();
  // σz = C_z z² with C_z = 0.010 / 142² mm⁻¹.
  EXPECT_NEAR(predicted_sigma_z_mm(s, {142.0, 0.0, 0.0, 0.0}), 0.010, 1e-9);
  EXPECT_NEAR(predicted_sigma_z_mm(s, {300.0, 0.0, 0.0, 0.0}), 0.044634001, 1e-8);
}

TEST(SensorModel, PrecisionGrowsAsInverseCosineOfYzIncidence) {
  const SensorModel s = testing::thesis_sensor();
  // eq. 3.4: 0.010 / cos 30° = 0.011547 mm.
  EXPECT_NEAR(predicted_sigma_z_mm(s, {142.0, 0.0, 0.0, 30 * kDeg}), 0.0115470054, 1e-9);
  // No inclination effect in the scan plane below t_xz.
  EXPECT_NEAR(predicted_sigma_z_mm(s, {142.0, 0.0, 50 * kDeg, 0.0}), 0.010, 1e-9);
}

TEST(SensorModel, GrazingThresholdsCutTheMeasurement) {
  const SensorModel s = testing::thesis_sensor();
  EXPECT_TRUE(std::isinf(predicted_sigma_z_mm(s, {142.0, 0.0, 0.0, 61 * kDeg})));
  EXPECT_TRUE(std::isfinite(predicted_sigma_z_mm(s, {142.0, 0.0, 0.0, 59 * kDeg})));
  EXPECT_TRUE(std::isinf(predicted_sigma_z_mm(s, {142.0, 0.0, 71 * kDeg, 0.0})));
  EXPECT_TRUE(std::isfinite(predicted_sigma_z_mm(s, {142.0, 0.0, 69 * kDeg, 0.0})));
}

TEST(SensorModel, CompliantDepthIsWherePrecisionOrDensityRunsOut) {
  // Thesis sensor and spec (50 um, 2 samples/mm2). Precision: C_z z^2 <= 0.050 up to z = sqrt(0.050 / C_z) =
  // 317.52 mm. Density, with a sweep of L: (z Phi_x / 255)^2 + (L / 255)^2 <= 1 / 2, so z <= 318.40 mm at
  // L = 100, 212.34 mm at L = 150; at L = 200 the profile spacing alone (0.784 mm) is too coarse.
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const FrustumTerms f(s);
  EXPECT_NEAR(compliant_depth_max_mm(s, f, spec, 100.0), 317.5217, 1e-3);
  EXPECT_NEAR(compliant_depth_max_mm(s, f, spec, 150.0), 212.3392, 1e-3);
  EXPECT_EQ(compliant_depth_max_mm(s, f, spec, 200.0), 0.0);
  // The bound is tight: a surface square to the boresight passes just inside it and fails just beyond.
  const Eigen::Vector3d up(0, 0, 1);
  EXPECT_TRUE(test_point(s, spec, 100.0, {0, 0, -317.4}, up).compliant);
  EXPECT_FALSE(test_point(s, spec, 100.0, {0, 0, -317.7}, up).compliant);
  EXPECT_TRUE(test_point(s, spec, 150.0, {0, 0, -212.2}, up).compliant);
  EXPECT_FALSE(test_point(s, spec, 150.0, {0, 0, -212.5}, up).compliant);
}

TEST(SensorModel, DensityMatchesEquation38) {
  const SensorModel s = testing::thesis_sensor();
  // δx = 142·Φx/255 = 0.262414 mm, δy = 100/255 = 0.392157 mm, ρ = 1/(δx² + δy²) = 4.49138.
  EXPECT_NEAR(predicted_density_per_mm2(s, {142.0, 0.0, 0.0, 0.0}, 100.0), 4.4913775, 1e-6);
  // Both incidences 30°: both intervals grow by 1/cos 30°, ρ = 3.36853.
  EXPECT_NEAR(predicted_density_per_mm2(s, {142.0, 0.0, 30 * kDeg, 30 * kDeg}, 100.0), 3.3685332, 1e-6);
  // Scan angle φ lengthens the slant range: R_xz = z / cos φ.
  const double phi = 10 * kDeg;
  const double dx = 142.0 / std::cos(phi) * s.fov_x_rad / 255, dy = 100.0 / 255;
  EXPECT_NEAR(predicted_density_per_mm2(s, {142.0, phi, 0.0, 0.0}, 100.0), 1.0 / (dx * dx + dy * dy), 1e-9);
}

TEST(SensorModel, DesignScanLengthMeetsDensityAtDesignIncidence) {
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const double r = 142.0 * 1.02;
  const double l = design_scan_length_mm(s, spec, r, 30 * kDeg);
  EXPECT_NEAR(l, 140.44833, 1e-4);  // sqrt(1/ρ - δx²)·cos30°·255
  EXPECT_NEAR(predicted_density_per_mm2(s, {r, 0.0, 30 * kDeg, 30 * kDeg}, l), spec.density_per_mm2, 1e-9);
  // At 407 mm the x interval alone breaks 2 samples/mm² at 30°: the shortest scan is returned.
  EXPECT_EQ(design_scan_length_mm(s, spec, 407.0, 30 * kDeg), s.scan_length_min_mm);
}

TEST(SensorModel, AimedScanLengthKeepsDensityWhereTheAimIsSeenObliquely) {
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const Eigen::Matrix3d camera = Eigen::Matrix3d::Identity();  // looking down −z: a facing normal has n.z > 0
  const double r = 145.0;
  // Square to the boresight: the design incidence's length, sqrt(1/ρ − δx²)·cos 30°·255, δx = 145·Φx/255/cos 30°.
  EXPECT_NEAR(aimed_scan_length_mm(s, spec, r, camera, {0, 0, 1}, 30 * kDeg), design_scan_length_mm(s, spec, r, 30 * kDeg), 1e-9);
  EXPECT_NEAR(design_scan_length_mm(s, spec, r, 30 * kDeg), 140.4118, 1e-3);
  // 62° in the x-z plane (a face turned to the plate, seen level): δx = 145·0.0018480/cos 62° = 0.57077 mm,
  // δy = sqrt(0.5 − 0.32578) = 0.41740 mm at cos 30° (y-z plane at the design): L = 0.41740·0.86603·255 = 92.18 mm.
  const Eigen::Vector3d n_xz(std::sin(62 * kDeg), 0, std::cos(62 * kDeg));
  const double l_xz = aimed_scan_length_mm(s, spec, r, camera, n_xz, 30 * kDeg);
  EXPECT_NEAR(l_xz, 92.18, 0.01);
  EXPECT_NEAR(predicted_density_per_mm2(s, {r, 0.0, 62 * kDeg, 30 * kDeg}, l_xz), spec.density_per_mm2, 1e-9);
  // The design length there gives 1/(0.32578 + (140.41/255)²) = 1.59 samples/mm²: the view measured nothing of its aim.
  EXPECT_NEAR(predicted_density_per_mm2(s, {r, 0.0, 62 * kDeg, 0.0}, 140.4118), 1.590, 1e-3);
  // 62° in the y-z plane: δx at 30° (0.30941 mm), δy = sqrt(0.5 − 0.09573) = 0.63582 mm: L = 0.63582·cos 62°·255 = 76.12 mm.
  const Eigen::Vector3d n_yz(0, std::sin(62 * kDeg), std::cos(62 * kDeg));
  EXPECT_NEAR(aimed_scan_length_mm(s, spec, r, camera, n_yz, 30 * kDeg), 76.12, 0.01);
  // A surface turned away from the view: the design length.
  EXPECT_NEAR(aimed_scan_length_mm(s, spec, r, camera, {0, 0, -1}, 30 * kDeg), design_scan_length_mm(s, spec, r, 30 * kDeg), 1e-9);
  // So grazing that no length meets the density: the shortest sweep.
  const Eigen::Vector3d n_80(std::sin(80 * kDeg), 0, std::cos(80 * kDeg));
  EXPECT_EQ(aimed_scan_length_mm(s, spec, 300.0, camera, n_80, 30 * kDeg), s.scan_length_min_mm);
}

TEST(SensorModel, PointTestFrustumFacingAndIncidence) {
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const Eigen::Vector3d up(0, 0, 1);  // facing the camera
  // On the boresight at 150 mm: in frustum, facing, compliant.
  PointTest t = test_point(s, spec, 100.0, {0, 0, -150}, up);
  EXPECT_TRUE(t.in_frustum && t.facing && t.compliant);
  EXPECT_NEAR(t.sigma_z_mm, 4.959333465582226e-07 * 150 * 150, 1e-12);
  // Beyond R_max, before R_min, outside the fan, beyond the scan length.
  EXPECT_FALSE(test_point(s, spec, 100.0, {0, 0, -410}, up).in_frustum);
  EXPECT_FALSE(test_point(s, spec, 100.0, {0, 0, -140}, up).in_frustum);
  EXPECT_FALSE(test_point(s, spec, 100.0, {150 * std::tan(14 * kDeg), 0, -150}, up).in_frustum);
  EXPECT_TRUE(test_point(s, spec, 100.0, {150 * std::tan(13 * kDeg), 0, -150}, up).in_frustum);
  EXPECT_FALSE(test_point(s, spec, 100.0, {0, 51, -150}, up).in_frustum);
  // Facing away from the camera.
  EXPECT_FALSE(test_point(s, spec, 100.0, {0, 0, -150}, -up).facing);
  // Tilted 30° about x (normal in the y-z plane): θyz = 30°, θxz = 0.
  const Eigen::Vector3d tilt(0, std::sin(30 * kDeg), std::cos(30 * kDeg));
  t = test_point(s, spec, 100.0, {0, 0, -150}, tilt);
  EXPECT_NEAR(t.incidence.theta_yz_rad, 30 * kDeg, 1e-12);
  EXPECT_NEAR(t.incidence.theta_xz_rad, 0.0, 1e-12);
  // Tilted 65° about x: past t_yz = 60°, not compliant even though in frustum and facing.
  t = test_point(s, spec, 100.0, {0, 0, -150}, {0, std::sin(65 * kDeg), std::cos(65 * kDeg)});
  EXPECT_TRUE(t.in_frustum && t.facing);
  EXPECT_FALSE(t.compliant);
  // Off-axis point with a normal facing the laser: θxz = 0.
  const double phi = 10 * kDeg;
  const Eigen::Vector3d p(150 * std::tan(phi), 0, -150);
  t = test_point(s, spec, 100.0, p, Eigen::Vector3d(-std::sin(phi), 0, std::cos(phi)));
  EXPECT_NEAR(t.incidence.theta_xz_rad, 0.0, 1e-12);
  EXPECT_NEAR(t.incidence.phi_xz_rad, phi, 1e-12);
  // Laser at the point's y, receiver a baseline further along +y.
  t = test_point(s, spec, 100.0, {0, 20, -150}, up);
  EXPECT_DOUBLE_EQ(t.laser_y_mm, 20.0);
  EXPECT_DOUBLE_EQ(t.receiver_y_mm, 200.0);
}

TEST(SensorModel, PrecisionSpecLimitsRange) {
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  // 0.050 = C_z z²  ->  z = 142·√5 = 317.5 mm.
  EXPECT_NEAR(max_range_for_precision_mm(s, spec), 142.0 * std::sqrt(5.0), 1e-9);
  EXPECT_TRUE(test_point(s, spec, 20.0, {0, 0, -315}, {0, 0, 1}).in_frustum);
  EXPECT_FALSE(test_point(s, spec, 20.0, {0, 0, -320}, {0, 0, 1}).compliant);
}

TEST(Viewpoint, CameraFrameIsRightHandedAndTwistRotatesAboutBoresight) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, -3).normalized();
  for (double tw : {0.0, 0.7, 3.0}) {
    const Eigen::Matrix3d r = camera_rotation(axis, tw);
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-12);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
    EXPECT_NEAR((r.col(2) + axis).norm(), 0.0, 1e-12);  // boresight is camera -z
  }
  const Eigen::Vector3d dir(0, 0, 1);
  const double tw = twist_towards(axis, dir);
  const Eigen::Vector3d yc = camera_rotation(axis, tw).col(1);
  const Eigen::Vector3d want = (dir - dir.dot(axis) * axis).normalized();
  EXPECT_NEAR((yc - want).norm(), 0.0, 1e-12);
}

}  // namespace
}  // namespace scancell::planner

namespace scancell::planner {
namespace {

// The matrix's trig-free path must agree with eq. 3.4 and 3.8 written in angles.
TEST(SensorModel, PointTestAgreesWithTheAngleFormulas) {
  const SensorModel s = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int checked = 0;
  for (int k = 0; k < 20000; ++k) {
    const Eigen::Vector3d p(60 * u(rng), 60 * u(rng), -(275 + 130 * u(rng)));
    Eigen::Vector3d n(u(rng), u(rng), u(rng) + 0.8);
    n.normalize();
    const PointTest t = test_point(s, spec, 120.0, p, n);
    if (!t.facing || !std::isfinite(predicted_sigma_z_mm(s, t.incidence))) continue;
    ++checked;
    ASSERT_NEAR(t.sigma_z_mm, predicted_sigma_z_mm(s, t.incidence), 1e-12);
    ASSERT_NEAR(t.density_per_mm2, predicted_density_per_mm2(s, t.incidence, 120.0), 1e-9);
    ASSERT_EQ(t.compliant, t.sigma_z_mm <= spec.precision_mm && t.density_per_mm2 >= spec.density_per_mm2);
  }
  EXPECT_GT(checked, 5000);
}

}  // namespace
}  // namespace scancell::planner
