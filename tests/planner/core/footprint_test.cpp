// The closed loop's footprint prediction (issue 15): a row is credited to a view only when the view measures
// enough samples of what the row still lacks, whatever its vertex's own test says.
#include <algorithm>

#include <gtest/gtest.h>

#include "common/errors.hpp"
#include "planner/config.hpp"
#include "planner/core/footprint.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

/// A camera 150 mm straight above (x, 0) on the z = 0 plane, sweeping 60 mm along y.
Viewpoint above(double x) {
  Viewpoint v;
  v.position = Eigen::Vector3d(x, 0.0, 150.0);
  v.axis = -Eigen::Vector3d::UnitZ();
  v.twist_rad = twist_towards(v.axis, Eigen::Vector3d::UnitY());
  v.standoff_mm = 150.0;
  v.scan_length_mm = 60.0;
  return v;
}

std::uint32_t row_at(const RoughModel& rm, const Eigen::Vector3d& p) {
  std::uint32_t best = 0;
  for (std::uint32_t i = 0; i < rm.size(); ++i)
    if ((rm.points[i] - p).squaredNorm() < (rm.points[best] - p).squaredNorm()) best = i;
  return best;
}

struct Fixture {
  TriangleMesh plane = testing::flat_patch(200.0, 4.0);
  RoughModel rough = make_rough_model(plane);
  OcclusionScene scene{plane};
  SensorModel sensor = load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml"));
  ModelSpec spec = load_spec(testing::source_path("config/spec/thesis.yaml"));
  // The profile spans x ± 150·tan(fov_x/2) (36 mm) on the plane.
  double half_x = 150.0 * std::tan(0.5 * sensor.fov_x_rad);
};

/// The row at (60, 0) with five samples of its footprint along x at 58 … 62 mm.
RowFootprints five_samples(std::uint32_t row, std::uint32_t needed) {
  RowFootprints f;
  f.rows = {row};
  for (int k = 0; k < 5; ++k) {
    f.points.emplace_back(58.0 + k, 0.0, 0.0);
    f.normals.emplace_back(Eigen::Vector3d::UnitZ());
  }
  f.first = {0, 5};
  f.needed = {needed};
  return f;
}

std::vector<std::uint32_t> samples_in(const SampleCover& c, std::uint32_t column) {
  std::vector<std::uint32_t> out;
  c.matrix.columns[column].for_each([&](std::uint32_t r) {
    if (r >= c.n_rows) out.push_back(r - c.n_rows);
  });
  return out;
}

TEST(FootprintPrediction, ViewsAreCreditedWithTheSamplesTheyMeasureAndFinishRowsTogether) {
  const Fixture fx;
  const std::uint32_t row = row_at(fx.rough, {60.0, 0.0, 0.0});
  const std::uint32_t centre = row_at(fx.rough, {0.0, 0.0, 0.0});
  ASSERT_NEAR(fx.rough.points[row].x(), 60.0, 1e-9);
  // Frusta on the plane: A |x| < 36 (neither the vertex nor a sample); B 24 … 96 (all five); C from 59.5
  // (the vertex and the samples at 60, 61, 62); D from 60.5 (61 and 62, not the vertex); E up to 59.5 (58
  // and 59, not the vertex).
  const std::vector<Viewpoint> views{above(0.0), above(60.0), above(59.5 + fx.half_x), above(60.5 + fx.half_x),
                                     above(59.5 - fx.half_x)};
  const MeasurabilityMatrix m = build_measurability(fx.rough, fx.scene, fx.sensor, fx.spec, views);
  ASSERT_TRUE(m.columns[2].contains(row));   // the vertex test credits C with the row
  ASSERT_FALSE(m.columns[3].contains(row));  // and not D
  std::vector<double> weight(fx.rough.size(), 1.0);
  weight[row] = 10.0;
  const SampleCover c = cover_by_samples(m, weight, five_samples(row, 5), fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm);
  ASSERT_EQ(c.matrix.n_rows, fx.rough.size() + 5);
  EXPECT_TRUE(samples_in(c, 0).empty());
  EXPECT_EQ(samples_in(c, 1), (std::vector<std::uint32_t>{0, 1, 2, 3, 4}));
  EXPECT_EQ(samples_in(c, 2), (std::vector<std::uint32_t>{2, 3, 4}));
  EXPECT_EQ(samples_in(c, 3), (std::vector<std::uint32_t>{3, 4}));
  EXPECT_EQ(samples_in(c, 4), (std::vector<std::uint32_t>{0, 1}));
  // The row itself leaves the cover; its weight is shared by its samples. Other rows keep theirs.
  EXPECT_EQ(c.weight[row], 0.0);
  for (std::uint32_t s = 0; s < 5; ++s) EXPECT_DOUBLE_EQ(c.weight[fx.rough.size() + s], 2.0);
  for (std::size_t j = 0; j < views.size(); ++j) {
    EXPECT_FALSE(c.matrix.columns[j].contains(row));
    EXPECT_EQ(c.matrix.columns[j].contains(centre), m.columns[j].contains(centre));
  }
  // Finished: all five samples by B alone, or by C and E together (neither alone), not by C and D.
  auto finished = [&](std::uint32_t needed, std::vector<std::uint32_t> chosen) {
    return finished_rows(c, five_samples(row, needed), chosen)[row] != 0;
  };
  EXPECT_TRUE(finished(5, {1}));
  EXPECT_FALSE(finished(5, {2}));
  EXPECT_FALSE(finished(5, {4}));
  EXPECT_TRUE(finished(5, {2, 4}));
  EXPECT_FALSE(finished(5, {2, 3}));
  EXPECT_TRUE(finished(3, {2}));
  EXPECT_TRUE(finished(2, {3}));  // D, whose vertex test fails
  // A view is said to measure the finished rows it contributes samples to.
  const std::vector<std::uint8_t> done = finished_rows(c, five_samples(row, 5), {2, 4});
  const auto rows_c = column_rows(c, five_samples(row, 5), 2, done), rows_a = column_rows(c, five_samples(row, 5), 0, done);
  EXPECT_TRUE(std::binary_search(rows_c.begin(), rows_c.end(), row));
  EXPECT_FALSE(std::binary_search(rows_a.begin(), rows_a.end(), row));
}

// With every row by samples, a single shot tests a sample only against the views that measure its row or a row
// within two triangles of it (cover_by_samples' `near_on`): the five samples beside their row get the elements
// the full test gives them, and a sample 40 mm from its row (G sees it, nothing near the row) is left out.
TEST(FootprintPrediction, WithTheTrianglesASampleIsTestedOnlyByTheViewsOfItsRowsSurroundings) {
  const Fixture fx;
  const std::uint32_t row = row_at(fx.rough, {60.0, 0.0, 0.0});
  const std::vector<Viewpoint> views{above(0.0),  above(60.0), above(59.5 + fx.half_x), above(60.5 + fx.half_x), above(59.5 - fx.half_x),
                                     above(110.0)};  // G: the plane from x = 74 mm
  const MeasurabilityMatrix m = build_measurability(fx.rough, fx.scene, fx.sensor, fx.spec, views);
  const std::vector<double> weight(fx.rough.size(), 1.0);
  RowFootprints f = five_samples(row, 5);
  f.points.emplace_back(100.0, 0.0, 0.0);
  f.normals.emplace_back(Eigen::Vector3d::UnitZ());
  f.first = {0, 6};
  const SampleCover full = cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm);
  const SampleCover near =
      cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm, nullptr, nullptr, &fx.rough.triangles);
  EXPECT_EQ(samples_in(full, 1), (std::vector<std::uint32_t>{0, 1, 2, 3, 4}));
  // D (from 60.5 mm) misses the row's vertex and measures its neighbour at 64 mm: all its samples are tested.
  EXPECT_EQ(samples_in(full, 3), (std::vector<std::uint32_t>{3, 4, 5}));
  EXPECT_EQ(samples_in(full, 5), (std::vector<std::uint32_t>{5}));
  for (std::uint32_t j = 0; j < 5; ++j) EXPECT_EQ(samples_in(near, j), samples_in(full, j)) << "view " << j;
  EXPECT_TRUE(samples_in(near, 5).empty());
  for (std::uint32_t j = 0; j < views.size(); ++j)
    for (std::uint32_t r = 0; r < fx.rough.size(); ++r) ASSERT_EQ(near.matrix.columns[j].contains(r), full.matrix.columns[j].contains(r));
  // Triangles that are not the model's are refused by the row they name.
  std::vector<Triangle> wrong = fx.rough.triangles;
  wrong[7][1] = m.n_rows + 2;
  try {
    cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm, nullptr, nullptr, &wrong);
    ADD_FAILURE() << "triangles past the rows accepted";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("names row " + std::to_string(m.n_rows + 2)), std::string::npos) << e.what();
  }
}

// The same rule over many rows and views, against the plane's own triangles walked here: a sample is tested
// by a view exactly when the view measures a row within two triangle rings of the sample's row. Rows every
// 8 mm along y = 0 with samples 5 and 14 mm either side; frustum edges fall at assorted distances from them.
TEST(FootprintPrediction, ASampleIsTestedExactlyWhenAViewMeasuresARowWithinTwoRingsOfItsRow) {
  const Fixture fx;
  RowFootprints f;
  for (double x = -80.0; x <= 80.0; x += 8.0) {
    f.rows.push_back(row_at(fx.rough, {x, 0.0, 0.0}));
    for (const double dx : {-14.0, -5.0, 0.0, 5.0, 14.0}) {
      f.points.emplace_back(x + dx, 0.0, 0.0);
      f.normals.emplace_back(Eigen::Vector3d::UnitZ());
    }
    f.first.push_back(static_cast<std::uint32_t>(f.points.size()));
    f.needed.push_back(1);
  }
  std::vector<Viewpoint> views;
  for (const double x : {-70.0, -33.0, 0.0, 21.5, 47.0, 59.5 + fx.half_x, 80.0}) views.push_back(above(x));
  const MeasurabilityMatrix m = build_measurability(fx.rough, fx.scene, fx.sensor, fx.spec, views);
  const std::vector<double> weight(fx.rough.size(), 1.0);
  const SampleCover full = cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm);
  const SampleCover near =
      cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm, nullptr, nullptr, &fx.rough.triangles);
  // Rows within two rings of each footprint row, by the triangles' edges.
  std::vector<std::vector<std::uint32_t>> ring(fx.rough.size());
  for (const auto& t : fx.rough.triangles)
    for (int a = 0; a < 3; ++a) ring[t[a]].push_back(t[(a + 1) % 3]), ring[t[(a + 1) % 3]].push_back(t[a]);
  std::size_t kept = 0, left_out = 0;
  for (std::size_t k = 0; k < f.size(); ++k) {
    std::vector<std::uint32_t> within{f.rows[k]};
    for (int g = 0; g < 2; ++g) {
      const std::vector<std::uint32_t> so_far = within;
      for (const auto r : so_far) within.insert(within.end(), ring[r].begin(), ring[r].end());
    }
    for (std::uint32_t j = 0; j < views.size(); ++j) {
      const bool near_measured = std::any_of(within.begin(), within.end(), [&](std::uint32_t r) { return m.columns[j].contains(r); });
      for (std::uint32_t s = f.first[k]; s < f.first[k + 1]; ++s) {
        const bool measured = full.matrix.columns[j].contains(full.n_rows + s);
        ASSERT_EQ(near.matrix.columns[j].contains(near.n_rows + s), measured && near_measured) << "view " << j << ", sample " << s;
        kept += measured && near_measured;
        left_out += measured && !near_measured;
      }
    }
  }
  // Both outcomes occur: samples in a frustum beside rows it does not reach are left out, the rest kept.
  EXPECT_GT(kept, 100u);
  EXPECT_GT(left_out, 0u);
}

TEST(FootprintPrediction, InconsistentFootprintsAreRefusedByWhatIsWrong) {
  const Fixture fx;
  const std::vector<Viewpoint> views{above(0.0)};
  const MeasurabilityMatrix m = build_measurability(fx.rough, fx.scene, fx.sensor, fx.spec, views);
  const std::vector<double> weight(fx.rough.size(), 1.0);
  auto refused = [&](const RowFootprints& f) {
    try {
      cover_by_samples(m, weight, f, fx.scene, fx.sensor, fx.spec, views, {}, fx.rough.mean_edge_mm);
    } catch (const DataError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  RowFootprints too_many = five_samples(3, 6);
  EXPECT_NE(refused(too_many).find("row 3 needs 6 of its 5 samples"), std::string::npos) << refused(too_many);
  RowFootprints past = five_samples(m.n_rows, 1);
  EXPECT_NE(refused(past).find("past the"), std::string::npos) << refused(past);
  RowFootprints offsets = five_samples(3, 1);
  offsets.first = {0, 4};
  EXPECT_NE(refused(offsets).find("offsets"), std::string::npos) << refused(offsets);
  // No footprints: the matrix and weights as they were.
  const SampleCover none = cover_by_samples(m, weight, RowFootprints{}, fx.scene, fx.sensor, fx.spec, views, {}, 1.0);
  EXPECT_EQ(none.matrix.nonzeros(), m.nonzeros());
  EXPECT_EQ(none.weight, weight);
}

// Where a replan aims at what a row lacks: the sample nearest the middle of the row's samples, with that
// sample's own normal, the stand-off given and the row credited; a row without samples gives none.
TEST(FootprintPrediction, AReplanAimsAtTheSampleNearestTheMiddleOfWhatARowLacks) {
  RowFootprints f;
  f.rows = {3, 5, 9};
  f.first = {0, 3, 3, 5};  // row 5 has no sample left
  f.points = {{0, 0, 0}, {1.2, 0, 0}, {3, 0, 0}, {0, 0, 10}, {0, 4, 10}};
  f.normals = {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}, {0, 0, -1}, {-1, 0, 0}};
  f.needed = {2, 0, 1};
  f.validate(10);
  const std::vector<AimPoint> aims = footprint_aims(f, 144.84);
  ASSERT_EQ(aims.size(), 2u);
  // Row 3: the middle is (1.4, 0, 0); the sample at 1.2 is nearest (0.2 against 1.4 and 1.6).
  EXPECT_EQ(aims[0].row, 3);
  EXPECT_TRUE(aims[0].point.isApprox(Eigen::Vector3d(1.2, 0, 0)));
  EXPECT_TRUE(aims[0].normal.isApprox(Eigen::Vector3d(0, 1, 0)));
  EXPECT_DOUBLE_EQ(aims[0].standoff_mm, 144.84);
  // Row 9: both samples lie 2 mm from the middle (0, 2, 10); the first is taken.
  EXPECT_EQ(aims[1].row, 9);
  EXPECT_TRUE(aims[1].point.isApprox(Eigen::Vector3d(0, 0, 10)));
  EXPECT_TRUE(aims[1].normal.isApprox(Eigen::Vector3d(0, 0, -1)));
}

}  // namespace
}  // namespace scancell::planner
