// Signed deviation from a reference surface (issue 19's inspection report), on a box with known offsets.
#include <cmath>

#include <gtest/gtest.h>

#include "common/errors.hpp"
#include "planner/reconstruction/inspection.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

TEST(Inspection, SignedDeviationFromABoxIsOutsidePositiveInsideNegative) {
  TriangleMesh box;
  testing::add_box(box, Eigen::Vector3d::Zero(), Eigen::Vector3d(100, 100, 100), 10.0);
  // 20 points 0.1 mm above the top face (outside), 20 points 0.05 mm inside the x = 0 face.
  std::vector<Eigen::Vector3d> pts;
  for (int k = 0; k < 20; ++k) pts.emplace_back(20 + 3 * k, 30 + 2 * k, 100.1);
  for (int k = 0; k < 20; ++k) pts.emplace_back(0.05, 25 + 2 * k, 70 - 2 * k);
  std::vector<double> each;
  const DeviationStats s = signed_deviation(pts, box, 0.06, &each);
  ASSERT_EQ(s.points, 40u);
  EXPECT_NEAR(each[0], 0.1, 1e-9);
  EXPECT_NEAR(each[39], -0.05, 1e-9);
  // mean (20·0.1 − 20·0.05)/40 = 0.025; rms √((20·0.01 + 20·0.0025)/40) = 0.0790569; the 38th of 40 sorted
  // magnitudes (95 %) is 0.1; half lie within 0.06 mm.
  EXPECT_NEAR(s.mean_mm, 0.025, 1e-9);
  EXPECT_NEAR(s.rms_mm, std::sqrt(0.00625), 1e-9);
  EXPECT_NEAR(s.p95_abs_mm, 0.1, 1e-9);
  EXPECT_NEAR(s.max_abs_mm, 0.1, 1e-9);
  EXPECT_DOUBLE_EQ(s.within_tolerance, 0.5);
  EXPECT_THROW(signed_deviation(pts, TriangleMesh{}, 0.1), DataError);
}

}  // namespace
}  // namespace scancell::planner
