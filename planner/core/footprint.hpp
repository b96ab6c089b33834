#pragma once
// The closed loop's footprint prediction (issue 15). A row of the rough model stands for its footprint (the
// cells MeasuredCoverage rasterises around it), and a row is measured when enough of those cells are filled.
// After a round, the rows left open are mostly *partly* filled: the part no executed view reached is what is
// missing, often a rim by the plate or the inside of a cleft. The vertex's own test says nothing about that
// part: it may pass for a view that will fill the same cells again. Predicting such a row by samples of its
// unfilled cells, each tested like a row (frustum, both lines of sight, eq. 3.4, eq. 3.8), tells the replan
// which views can finish it, and that none can before a view is spent on it.
#include <atomic>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "planner/core/cell_viewpoints.hpp"
#include "planner/core/measurability.hpp"

namespace scancell::planner {

/// Rows to predict by their footprint, with samples of what each still lacks.
struct RowFootprints {
  std::vector<std::uint32_t> rows;               // ascending
  std::vector<std::uint32_t> first{0};           // rows.size() + 1 offsets: row k's samples are first[k] .. first[k+1)
  std::vector<Eigen::Vector3d> points, normals;  // samples on the surface (object frame, mm; unit normals)
  std::vector<std::uint32_t> needed;             // per row: how many of its samples one view must measure

  std::size_t size() const { return rows.size(); }
  /// Throws DataError naming the first inconsistency (offsets, sizes, a row past `n_rows`, needed > samples).
  void validate(std::uint32_t n_rows) const;
};

/// The matrix a replan covers (issue 15): each footprint row gives way to its samples, rows of their own
/// appended after the rough model's (sample s is row n_rows + s), each weighing the row's weight over its
/// sample count. A view gains by the share of a row it would fill, so that views which finish a row together
/// are found as well as one that finishes it alone. The samples' elements are the matrix builder's element
/// test with the same settings; with `plain` (the test without the free-space margin), a sample the margin
/// leaves without a view keeps the plain test's elements, as a row does. With `near_on` (the rough model's
/// triangles; a single shot's footprints, whose rows `matrix` was built for in full), a sample is tested only
/// against the columns that measure its row or a row within two triangles of it: 4 samples of every row in a single
/// shot were 107 M point tests, most of them for views that see nothing of the row's neighbourhood.
struct SampleCover {
  MeasurabilityMatrix matrix;  // the rough model's rows (footprint rows left empty), then the samples
  std::vector<double> weight;  // per row of `matrix`
  std::uint32_t n_rows = 0;    // the rough model's rows
  std::vector<std::uint32_t> owner;  // per sample: its entry in the footprints (not the row itself)
};

/// Where a replan aims views at what each footprint row lacks (cell_viewpoints_at): the sample nearest the
/// middle of the row's samples, a point on the surface with that surface's normal, at `standoff_mm`, credited
/// to the row. One per row with samples; `f` is taken as validated.
std::vector<AimPoint> footprint_aims(const RowFootprints& f, double standoff_mm);

SampleCover cover_by_samples(const MeasurabilityMatrix& matrix, const std::vector<double>& row_weight, const RowFootprints& footprints,
                             const OcclusionScene& scene, const SensorModel& sensor, const ModelSpec& spec,
                             const std::vector<Viewpoint>& candidates, const MatrixSettings& settings, double mean_edge_mm,
                             const std::atomic<int>* cancel = nullptr, const Countermeasures* plain = nullptr,
                             const std::vector<Triangle>* near_on = nullptr);

/// The footprint rows `views` (columns of `c.matrix`) finish together: at least needed[k] of a row's samples
/// measured by one or another of them. One flag per rough-model row (rows without a footprint: 0).
std::vector<std::uint8_t> finished_rows(const SampleCover& c, const RowFootprints& footprints, const std::vector<std::uint32_t>& views);

/// A column of `c.matrix` in rough-model rows: its own rows, and the footprint rows of its samples that
/// `finished` (finished_rows) marks. Sorted, without repeats.
std::vector<std::uint32_t> column_rows(const SampleCover& c, const RowFootprints& footprints, std::uint32_t column,
                                       const std::vector<std::uint8_t>& finished);

/// What the registration constraint counts two views' overlap in on a cover by samples (eq. 4.1-4.2,
/// MeasurabilityMatrix::overlap): the rough model's rows with `row_weight`, a footprint row shared by two
/// views when each measures some of its samples. So a box's edge row still lets views of its two faces
/// register, as its vertex does when judged by the vertex: split into samples, neither view measures the
/// other's face, and at the thesis spec no view measures both (a 120 x 80 x 40 box at 600 rows stopped at
/// 0.26 with samples counted apart; docs/quality.md "Crease rows in free space").
std::shared_ptr<const OverlapRows> overlap_by_footprint_rows(const SampleCover& c, const RowFootprints& footprints,
                                                             const std::vector<double>& row_weight);

}  // namespace scancell::planner
