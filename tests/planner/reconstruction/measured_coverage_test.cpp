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

using testing::sampling;
using testing::thesis_sensor;
using testing::thesis_spec;

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

std::uint32_t row_near(const RoughModel& rm, const Eigen::Vector3d& p) {
  std::uint32_t best = 0;
  for (std::uint32_t i = 0; i < rm.size(); ++i)
    if ((rm.points[i] - p).squaredNorm() < (rm.points[best] - p).squaredNorm()) best = i;
  return best;
}

/// A noise-free image of the z = 0 plane seen from 150 mm straight above: samples every 0.25 mm in x (along
/// the profile) and y (across profiles) over |x|, |y| ≤ 20 mm, none where |x| < gap_mm / 2.
RangeImage plane_with_a_gap(double gap_mm) {
  RangeImage img;
  img.columns = img.rows = 161;
  img.pose.camera_to_object.translation() = Eigen::Vector3d(0, 0, 150);
  img.pose.scan_length_mm = 40.0;
  img.samples.resize(static_cast<std::size_t>(img.columns) * static_cast<std::size_t>(img.rows));
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const float x = -20.0f + 0.25f * static_cast<float>(i), y = -20.0f + 0.25f * static_cast<float>(j);
      RangeSample& s = img.samples[static_cast<std::size_t>(j) * static_cast<std::size_t>(img.columns) + static_cast<std::size_t>(i)];
      s.measured = std::abs(x) > 0.5 * gap_mm;
      s.object_mm = Eigen::Vector3f(x, y, 0.0f);
      s.camera_mm = Eigen::Vector3f(x, y, -150.0f);
      s.sigma_z_mm = 0.01f;
    }
  return img;
}

TEST(MeasuredCoverage, AGapUnderOneAndAHalfCellsIsBridgedAWiderOneIsNot) {
  // Cells are 1/√2 = 0.707 mm (the spec's 2 /mm²); the row at the origin has cell centres at x = 0, ±0.707,
  // ±1.414 mm and ±2.12 mm. A compliant sample fills the cells
  // within ¾ cell (0.53 mm) of it along each axis. A 0.9 mm gap centred on x = 0 leaves the middle column
  // 0.45 mm from the nearest samples: filled, the row measured (rounding each sample to its own cell alone
  // left that column, 5 of the row's 31 cells, empty). A 1.5 mm gap leaves it 0.75 mm from them: empty, and
  // the row open; the columns at ±0.707 mm are 0.043 mm from the samples at ±0.75 mm.
  const TriangleMesh plane = testing::flat_patch(200.0, 4.0);
  const RoughModel rough = make_rough_model(plane);
  const std::uint32_t origin = row_near(rough, {0, 0, 0});
  ASSERT_NEAR(rough.points[origin].norm(), 0.0, 1e-9);
  MeasuredCoverage narrow(rough, thesis_spec()), wide(rough, thesis_spec());
  narrow.add(plane_with_a_gap(0.9));
  wide.add(plane_with_a_gap(1.5));
  EXPECT_EQ(narrow.row_fraction(origin), 1.0);
  EXPECT_TRUE(narrow.measured(origin));
  EXPECT_FALSE(wide.measured(origin));
  // What it lacks is the middle column and nothing else: its five cells, y = 0, ±0.707, ±1.414 mm.
  const RowFootprints lacks = wide.open_footprints({origin}, 64);
  ASSERT_EQ(lacks.size(), 1u);
  EXPECT_EQ(lacks.first[1], 5u);
  for (std::uint32_t k = 0; k < lacks.first[1]; ++k) EXPECT_NEAR(lacks.points[k].x(), 0.0, 1e-6) << lacks.points[k].transpose();
  const double cells = static_cast<double>(wide.footprint_cells(origin));
  EXPECT_DOUBLE_EQ(wide.row_fraction(origin), (cells - 5.0) / cells);
  // A row 4 mm off the gap is whole either way.
  const std::uint32_t aside = row_near(rough, {8, 0, 0});
  EXPECT_EQ(narrow.row_fraction(aside), 1.0);
  EXPECT_EQ(wide.row_fraction(aside), 1.0);
}

TEST(MeasuredCoverage, OpenFootprintsSampleWhatARowLacks) {
  // The view of the first test fills |x| < 36 mm. Cells are 1/√2 mm (the spec's 2 /mm²).
  const TriangleMesh plane = testing::flat_patch(200.0, 4.0);
  const RoughModel rough = make_rough_model(plane);
  MeasuredCoverage cov(rough, thesis_spec());
  cov.add(scan_plane_from(plane, 150.0, 60.0));
  const std::uint32_t inside = row_near(rough, {0, 0, 0}), edge = row_near(rough, {36, 0, 0}), beyond = row_near(rough, {60, 0, 0});
  ASSERT_TRUE(cov.measured(inside));
  ASSERT_GT(cov.row_fraction(edge), 0.2);
  ASSERT_LT(cov.row_fraction(edge), 0.9);
  ASSERT_EQ(cov.row_fraction(beyond), 0.0);
  const RowFootprints f = cov.open_footprints({beyond, inside, edge}, 8);
  // The measured row is left out; rows come in ascending order.
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f.rows, (std::vector<std::uint32_t>{std::min(edge, beyond), std::max(edge, beyond)}));
  for (std::size_t k = 0; k < f.size(); ++k) {
    const std::uint32_t r = f.rows[k];
    EXPECT_EQ(f.first[k + 1] - f.first[k], 8u);
    for (std::uint32_t s = f.first[k]; s < f.first[k + 1]; ++s) {
      // On the plane, within the row's footprint (the vertex, edge midpoints and centroids: ±2 mm and a half
      // cell), with the plane's normal.
      EXPECT_NEAR(f.points[s].z(), 0.0, 1e-6);
      EXPECT_LE((f.points[s] - rough.points[r]).cwiseAbs().maxCoeff(), 2.0 + 0.36);
      EXPECT_NEAR(f.normals[s].z(), 1.0, 1e-6);
      // The edge row's samples are all where the view did not reach.
      if (r == edge) {
        EXPECT_GT(f.points[s].x(), 36.0 - 0.36) << f.points[s].transpose();
      }
    }
    // A view must fill what the row lacks of 0.9 of its cells: an empty row of c cells needs ⌈0.9 c⌉ of its
    // c (all but the last tenth), i.e. ⌈8·⌈0.9 c⌉/c⌉ of 8 samples.
    const double c = static_cast<double>(cov.footprint_cells(r));
    const double filled = cov.row_fraction(r) * c;
    const double lacks = std::ceil(0.9 * c - 1e-9) - filled;
    EXPECT_EQ(f.needed[k], static_cast<std::uint32_t>(std::ceil(8.0 * lacks / (c - filled) - 1e-9))) << "row " << r << ", " << c << " cells";
  }
  // The empty row: 8 of its 8 samples whenever it has fewer than 80 cells (⌈0.9 c⌉/c > 7/8).
  const std::size_t k_beyond = f.rows[0] == beyond ? 0 : 1;
  ASSERT_LT(cov.footprint_cells(beyond), 80u);
  EXPECT_EQ(f.needed[k_beyond], 8u);
}

TEST(MeasuredCoverage, OpenFootprintSamplesLieOnTheFacesOfABentFootprint) {
  // A 90° roof ridge along y (z = −|x|): the ridge row's tangent plane is z = 0, its footprint bends down
  // both faces. Its samples lie on the faces, each with its face's normal, not in the tangent plane.
  TriangleMesh roof = testing::flat_patch(40.0, 4.0);
  for (auto& v : roof.vertices) v.z() = -std::abs(v.x());
  const RoughModel rough = make_rough_model(roof);
  MeasuredCoverage cov(rough, thesis_spec());
  const std::uint32_t ridge = row_near(rough, {0, 0, 0});
  const RowFootprints f = cov.open_footprints({ridge}, 64);
  ASSERT_EQ(f.size(), 1u);
  std::size_t off_ridge = 0;
  for (std::uint32_t s = f.first[0]; s < f.first[1]; ++s) {
    const Eigen::Vector3d& p = f.points[s];
    EXPECT_NEAR(p.z(), -std::abs(p.x()), 1e-6) << p.transpose();
    if (std::abs(p.x()) > 0.1) {
      ++off_ridge;
      EXPECT_NEAR(f.normals[s].dot(Eigen::Vector3d(p.x() > 0 ? 1.0 : -1.0, 0.0, 1.0).normalized()), 1.0, 1e-6);
    }
  }
  EXPECT_GT(off_ridge, 4u);
}

// A single shot's whole-row footprints (matrix.footprint_samples with footprint_sample_area_mm2):
// one sample per that much of a row's area, and a row under two samples' worth left to its vertex. On a
// 40 mm flat patch of 4 mm steps an interior row is a third of six 8 mm² triangles, 16 mm², an edge row a
// third of three, 8 mm², a corner less. At 5 mm² a sample, the 9 × 9 interior rows take 3 samples each and
// the rest none; with no area, every row takes the cap.
TEST(MeasuredCoverage, WholeRowFootprintsSampleEachRowByItsArea) {
  const TriangleMesh plane = testing::flat_patch(40.0, 4.0);
  const RoughModel rough = make_rough_model(plane);
  const ModelSpec spec = thesis_spec();
  std::vector<std::uint32_t> interior;
  for (std::uint32_t r = 0; r < rough.size(); ++r) {
    const Eigen::Vector3d a = rough.points[r].cwiseAbs();
    const bool inside = a.maxCoeff() < 19.0, corner = a.head<2>().minCoeff() > 19.0;
    if (inside) interior.push_back(r);
    if (corner) EXPECT_LT(rough.area_mm2[r], 8.0) << "row at " << rough.points[r].transpose();
    else EXPECT_NEAR(rough.area_mm2[r], inside ? 16.0 : 8.0, 1e-9) << "row at " << rough.points[r].transpose();
  }
  ASSERT_EQ(interior.size(), 81u);
  const RowFootprints by_area = whole_row_footprints(rough, spec, sampling(8, 5.0));
  EXPECT_EQ(by_area.rows, interior);
  for (std::size_t k = 0; k < by_area.size(); ++k) EXPECT_EQ(by_area.first[k + 1] - by_area.first[k], 3u);
  const RowFootprints every = whole_row_footprints(rough, spec, sampling(8));
  EXPECT_EQ(every.size(), rough.size());
  for (std::size_t k = 0; k < every.size(); ++k)
    EXPECT_EQ(every.first[k + 1] - every.first[k], std::min<std::size_t>(8, MeasuredCoverage(rough, spec).footprint_cells(every.rows[k])));
  EXPECT_THROW(whole_row_footprints(rough, spec, sampling(0)), ConfigError);
  EXPECT_THROW(whole_row_footprints(rough, spec, sampling(8, -1.0)), ConfigError);
}

// Crease rows keep their samples whatever their area: on a 90° roof (z = −|x|) with no row two samples'
// worth, the footprints are exactly the ridge's rows, 4 samples each on the two faces.
TEST(MeasuredCoverage, WholeRowFootprintsKeepTheCreaseRows) {
  TriangleMesh roof = testing::flat_patch(40.0, 4.0);
  for (auto& v : roof.vertices) v.z() = -std::abs(v.x());
  const RoughModel rough = make_rough_model(roof);
  const std::vector<std::uint32_t> ridge = crease_rows(rough, 40.0 * testing::kDeg);
  ASSERT_EQ(ridge.size(), 11u);
  for (auto r : ridge) EXPECT_NEAR(rough.points[r].x(), 0.0, 1e-9);
  const RowFootprints f = whole_row_footprints(rough, thesis_spec(), {8, 100.0, ridge, 4});
  EXPECT_EQ(f.rows, ridge);
  for (std::size_t k = 0; k < f.size(); ++k) EXPECT_EQ(f.first[k + 1] - f.first[k], 4u);
  EXPECT_TRUE(whole_row_footprints(rough, thesis_spec(), sampling(8, 100.0)).rows.empty());
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

// A replan by footprint samples (issue 15) on the same convex patch, its x >= 0 half open and not yet scanned:
// the views finish the open rows (predicted rows are open ones, nearly all of their area), every open row
// stays measurable (the rows give way to their samples in the cover, and a row is unmeasurable only when
// none of its samples is), and the measured half is left alone.
TEST(Replan, OpenRowsArePlannedByTheirFootprintSamples) {
  const TriangleMesh patch = convex_patch(100.0, 0.04, 2.0);
  const SensorModel sensor = thesis_sensor();
  const ModelSpec spec = thesis_spec();
  PlannerSettings settings;
  RoughModelOptions rough;
  rough.target_vertices = 400;
  const ViewPlan first = plan_views(patch, sensor, spec, settings, rough, 1);
  std::vector<std::uint8_t> half(first.rough.size(), 0);
  std::vector<std::uint32_t> open;
  double open_area = 0.0;
  for (std::uint32_t r = 0; r < first.rough.size(); ++r) {
    half[r] = first.rough.points[r].x() < 0.0;
    if (!half[r]) open.push_back(r), open_area += first.rough.area_mm2[r];
  }
  const MeasuredCoverage cov(first.rough, spec);
  const RowFootprints f = cov.open_footprints(open, 8);
  ASSERT_EQ(f.size(), open.size());
  const ViewPlan rest = plan_views(patch, sensor, spec, settings, rough, 1, nullptr, &half, nullptr, nullptr, &f);
  ASSERT_FALSE(rest.views.empty());
  double predicted = 0.0;
  for (auto r : rest.predicted_rows) {
    EXPECT_FALSE(half[r]) << "row " << r << " was measured";
    predicted += first.rough.area_mm2[r];
  }
  EXPECT_NEAR(predicted, rest.predicted_gain_mm2, 1e-6);
  EXPECT_GT(predicted, 0.9 * open_area);
  for (auto r : rest.cover.unmeasurable_rows) EXPECT_TRUE(half[r]) << "open row " << r << " listed as unmeasurable";
}

}  // namespace
}  // namespace scancell::planner
