// Distances between surfaces, for judging a rough model against its object: hand-checked point-to-triangle
// cases, and two concentric spheres whose Hausdorff distance is the difference of their radii.
#include <numbers>

#include <gtest/gtest.h>

#include "planner/geometry/surface_distance.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

TEST(SurfaceDistance, ClosestPointOnATriangleInEveryRegion) {
  const Eigen::Vector3d a(0, 0, 0), b(10, 0, 0), c(0, 10, 0);
  // Above the face: straight down.
  EXPECT_TRUE(closest_on_triangle({2, 3, 5}, a, b, c).isApprox(Eigen::Vector3d(2, 3, 0)));
  // Beyond a vertex, beyond an edge, beyond the hypotenuse.
  EXPECT_TRUE(closest_on_triangle({-3, -4, 1}, a, b, c).isApprox(a));
  EXPECT_TRUE(closest_on_triangle({5, -2, 0}, a, b, c).isApprox(Eigen::Vector3d(5, 0, 0)));
  EXPECT_TRUE(closest_on_triangle({8, 8, 0}, a, b, c).isApprox(Eigen::Vector3d(5, 5, 0)));
  EXPECT_TRUE(closest_on_triangle({20, -1, 0}, a, b, c).isApprox(b));
}

TEST(SurfaceDistance, ConcentricSpheresAreTheirRadiiApart) {
  // Fine spheres of radius 40 and 41 mm: every point of one is ~1 mm from the other (less the chords' sag,
  // 40 mm · (1 − cos(π/180)) < 0.01 mm at 180 segments); normals agree to a fraction of a degree.
  const TriangleMesh inner = testing::uv_sphere({0, 0, 0}, 40.0), outer = testing::uv_sphere({0, 0, 0}, 41.0);
  const SurfaceComparison s = compare_surfaces(inner, outer);
  EXPECT_NEAR(s.model_to_truth_max_mm, 1.0, 0.02);
  EXPECT_NEAR(s.model_to_truth_mean_mm, 1.0, 0.02);
  EXPECT_NEAR(s.truth_to_model_max_mm, 1.0, 0.02);
  EXPECT_NEAR(s.hausdorff_mm, 1.0, 0.02);
  EXPECT_LT(s.normal_error_p95_rad, 2.0 * std::numbers::pi / 180.0);
  EXPECT_EQ(s.model_vertices, inner.vertices.size());
  // A point far outside the grid still finds the sphere.
  const SurfaceIndex index(outer);
  EXPECT_NEAR(index.closest({300, 0, 0}).distance_mm, 259.0, 0.01);
  // Only the selected vertices of the model count on its side: the upper hemisphere.
  std::vector<std::uint8_t> upper(inner.vertices.size(), 0);
  for (std::size_t v = 0; v < upper.size(); ++v) upper[v] = inner.vertices[v].z() > 0.0;
  EXPECT_LT(compare_surfaces(inner, outer, upper).model_vertices, inner.vertices.size());
}

}  // namespace
}  // namespace scancell::planner
