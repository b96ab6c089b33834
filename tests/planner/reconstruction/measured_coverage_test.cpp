// Measured coverage on the rough model from acquired range images, and replanning for what is left.
#include <gtest/gtest.h>

#include "planner/sim/virtual_scanner.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "planner/plan.hpp"
#include "planner/sim/synthetic.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

SensorModel thesis_sensor() { return load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml")); }
ModelSpec thesis_spec() { return load_spec(testing::source_path("config/spec/thesis.yaml")); }

/// A view straight down onto the z = 0 plane from `height_mm`, sweeping ±L/2 along y.
RangeImage scan_plane_from(const TriangleMesh& plane, double height_mm, double scan_length_mm) {
  const OcclusionScene scene(plane);
  ScanPose pose;
  pose.camera_to_object.translation() = Eigen::Vector3d(0, 0, height_mm);  // camera z up: boresight -z
  pose.scan_length_mm = scan_length_mm;
  return virtual_scan(scene, thesis_sensor(), pose);
}

TEST(MeasuredCoverage, RowsInsideTheFootprintAreMeasuredAndNoneOutside) {
  // 200 mm square, 4 mm grid. From 150 mm the profile spans 2·150·tan(13.5°) = 72 mm across x and the sweep
  // 60 mm along y; σz = C_z·150² = 0.011 mm and ρ ≈ 1/(0.277² + 0.235²) = 7.6 /mm², both within the thesis
  // spec (0.05 mm, 2 /mm²). Rows whose whole footprint (±2 mm) lies inside are measured, rows wholly outside
  // are not, and the measured area is about the footprint's 72 × 60 mm of 200 × 200 mm.
  const TriangleMesh plane = testing::flat_patch(200.0, 4.0);
  const RoughModel rough = make_rough_model(plane);
  MeasuredCoverage cov(rough, thesis_spec());
  EXPECT_EQ(cov.coverage(), 0.0);
  EXPECT_GT(cov.add(scan_plane_from(plane, 150.0, 60.0)), 50000u);
  const double half_x = 150.0 * std::tan(0.5 * thesis_sensor().fov_x_rad);
  std::size_t inside = 0, outside = 0;
  for (std::size_t r = 0; r < rough.size(); ++r) {
    const Eigen::Vector3d& p = rough.points[r];
    if (std::abs(p.x()) < half_x - 3.0 && std::abs(p.y()) < 30.0 - 3.0 && std::abs(p.x()) < 98 && std::abs(p.y()) < 98) {
      EXPECT_TRUE(cov.measured(r)) << "row at " << p.transpose() << " fraction " << cov.row_fraction(r);
      ++inside;
    }
    if (std::abs(p.x()) > half_x + 3.0 || std::abs(p.y()) > 30.0 + 3.0) {
      EXPECT_EQ(cov.row_fraction(r), 0.0) << "row at " << p.transpose();
      ++outside;
    }
  }
  EXPECT_GT(inside, 200u);
  EXPECT_GT(outside, 2000u);
  const double expected = 2 * half_x * 60.0 / (200.0 * 200.0);
  EXPECT_NEAR(cov.coverage(), expected, 0.15 * expected);
  const auto flags = cov.measured_rows();
  EXPECT_EQ(cov.unmeasured_rows().size() + static_cast<std::size_t>(std::count(flags.begin(), flags.end(), 1)), rough.size());
}

TEST(MeasuredCoverage, SamplesOutsideTheSpecMeasureNothing) {
  // From 330 mm, σz = C_z·330² = 0.054 mm > 0.05 mm: every sample is valid, none is compliant.
  const TriangleMesh plane = testing::flat_patch(200.0, 4.0);
  const RoughModel rough = make_rough_model(plane);
  MeasuredCoverage cov(rough, thesis_spec());
  const RangeImage img = scan_plane_from(plane, 330.0, 60.0);
  EXPECT_GT(img.valid_count(), 50000u);
  EXPECT_EQ(cov.add(img), 0u);
  EXPECT_EQ(cov.coverage(), 0.0);
  // A stricter density spec than the view gives (7.6 /mm² at 150 mm) measures nothing either.
  ModelSpec dense = thesis_spec();
  dense.density_per_mm2 = 12.0;
  MeasuredCoverage strict(rough, dense);
  EXPECT_EQ(strict.add(scan_plane_from(plane, 150.0, 60.0)), 0u);
}

TEST(MeasuredCoverage, ARowFacingAwayFromTheLaserIsNotMeasuredThroughTheWall) {
  // Two parallel sheets 1 mm apart facing opposite ways (a thin wall): the scan from above measures the top
  // sheet only, although the bottom sheet's rows lie within the normal tolerance.
  TriangleMesh wall = testing::flat_patch(100.0, 4.0);
  TriangleMesh under = testing::flat_patch(100.0, 4.0);
  for (auto& v : under.vertices) v.z() = -1.0;
  for (auto& t : under.triangles) std::swap(t[1], t[2]);  // faces -z
  const std::size_t top_rows = wall.vertices.size();
  append_mesh(wall, under);
  const RoughModel rough = make_rough_model(wall);
  MeasuredCoverage cov(rough, thesis_spec());
  cov.add(scan_plane_from(wall, 150.0, 60.0));
  std::size_t top = 0, bottom = 0;
  for (std::size_t r = 0; r < rough.size(); ++r) (rough.points[r].z() > -0.5 ? top : bottom) += cov.measured(r);
  EXPECT_GT(top, 100u);
  EXPECT_EQ(bottom, 0u);
  (void)top_rows;
}

TEST(Replan, MeasuredRowsLeaveTheCover) {
  const TriangleMesh patch = convex_patch(100.0, 0.04, 2.0);
  const SensorModel sensor = thesis_sensor();
  const ModelSpec spec = thesis_spec();
  PlannerSettings settings;
  RoughModelOptions rough;
  rough.target_vertices = 400;
  const ViewPlan first = plan_views(patch, sensor, spec, settings, rough, 1);
  ASSERT_GT(first.views.size(), 1u);
  // Everything measured: nothing left to plan.
  std::vector<std::uint8_t> all(first.rough.size(), 1);
  const ViewPlan none = plan_views(patch, sensor, spec, settings, rough, 1, nullptr, &all);
  EXPECT_TRUE(none.views.empty());
  // Half measured (x < 0): the new views' cover claims only rows with x >= 0, and fewer views than before.
  std::vector<std::uint8_t> half(first.rough.size(), 0);
  for (std::size_t r = 0; r < first.rough.size(); ++r) half[r] = first.rough.points[r].x() < 0.0;
  const ViewPlan rest = plan_views(patch, sensor, spec, settings, rough, 1, nullptr, &half);
  ASSERT_FALSE(rest.views.empty());
  EXPECT_LT(rest.views.size(), first.views.size());
  double left = 0.0;
  for (std::size_t r = 0; r < half.size(); ++r) left += half[r] ? 0.0 : first.rough.area_mm2[r];
  double gained = 0.0;
  for (double g : rest.cover.gain_weight) {
    EXPECT_GT(g, 0.0);
    gained += g;
  }
  EXPECT_LE(gained, left + 1e-6);
  EXPECT_GT(gained, 0.9 * left);
  // A flag vector of another rough model is refused.
  std::vector<std::uint8_t> wrong(first.rough.size() + 1, 0);
  EXPECT_THROW(plan_views(patch, sensor, spec, settings, rough, 1, nullptr, &wrong), DataError);
}

}  // namespace
}  // namespace scancell::planner
