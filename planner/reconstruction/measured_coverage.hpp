#pragma once
// Measured coverage on the rough model (thesis table 3.1, "update the model"): which rows of the rough model
// the acquired range images have measured to the specification. A row (rough vertex s_i) stands for its
// share of the surface, its footprint: the part of each adjacent triangle nearer s_i (vertex, edge midpoints,
// centroid). The footprint is rasterised in s_i's tangent plane into cells of the spec's sample spacing
// 1/√ρ; a spec-compliant sample (σz ≤ precision, local density ≥ ρ, eq. 3.4/3.8 from the samples themselves)
// fills the cells within ¾ of a cell of where it projects (the verifier's ¾-chord reach) when it lies within
// the normal tolerance of the row's plane and the row faces the laser that measured it. A row is measured
// when at least `row_fraction` of its footprint cells are filled (the tolerance grows by how far a footprint
// bent over an edge leaves its own tangent plane). The planner's estimate counts rows the same way, so the
// two are directly comparable.
#include <cstdint>
#include <vector>

#include "planner/core/footprint.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/core/sensor.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

struct CoverageOptions {
  double row_fraction = 0.9;        // footprint fraction that makes a row measured
  double normal_tolerance_mm = 0.0; // how far off the row's tangent plane a sample may lie; 0: max(2, edge/2)
};

class MeasuredCoverage {
 public:
  MeasuredCoverage(const RoughModel& rough, const ModelSpec& spec, CoverageOptions options = {});

  /// Adds one range image (object-frame samples from the executed poses); returns the compliant samples
  /// that landed on some row. `compliant`, if given (one flag per sample), replaces the precision and
  /// density tests: to count the same samples at other positions (verification from the true hit points).
  std::size_t add(const RangeImage& image, const std::vector<std::uint8_t>* compliant = nullptr);

  /// Per sample of `image`: 1 where it meets the spec's precision and sampling density (the test add() makes).
  static std::vector<std::uint8_t> compliant_samples(const RangeImage& image, const ModelSpec& spec);

  std::size_t rows() const { return footprint_.size(); }
  /// Filled fraction of a row's footprint, 0..1.
  double row_fraction(std::size_t row) const;
  bool measured(std::size_t row) const { return row_fraction(row) >= options_.row_fraction - 1e-12; }
  std::vector<std::uint8_t> measured_rows() const;
  std::vector<std::uint32_t> unmeasured_rows() const;
  /// Area of the measured rows over the rough model's area.
  double coverage() const;
  std::size_t footprint_cells(std::size_t row) const { return footprint_[row].size(); }
  /// What `rows` (those not yet measured; measured ones are skipped) still lack, for a replan's footprint
  /// prediction (planner/core/footprint.hpp): per row up to `max_samples` of its unfilled cells, each as the
  /// cell centre on the rough-model triangle it came from with that triangle's normal, and how many of them one
  /// view must measure to bring the row to `row_fraction` (the share it lacks of its unfilled cells, rounded up).
  RowFootprints open_footprints(const std::vector<std::uint32_t>& rows, std::size_t max_samples) const;
  /// The same with a cap per row: rows[k] up to max_samples[k] samples (`rows` ascending, without repeats).
  RowFootprints open_footprints(const std::vector<std::uint32_t>& rows, const std::vector<std::size_t>& max_samples) const;

 private:
  struct Grid;
  std::vector<Eigen::Vector3d> points_, normals_, u_, v_;
  std::vector<double> area_;
  double total_area_ = 0.0;
  ModelSpec spec_;
  CoverageOptions options_;
  double cell_ = 1.0, tolerance_ = 2.0, reach_ = 1.0;
  std::vector<std::vector<std::uint32_t>> footprint_;  // sorted cell keys per row
  std::vector<std::vector<Eigen::Vector3f>> cell_point_, cell_normal_;  // per footprint cell: on its triangle
  std::vector<double> bend_;                           // per row: how far its footprint leaves its tangent plane
  std::vector<std::vector<std::uint8_t>> filled_;      // per footprint cell
  std::vector<std::size_t> filled_count_;
  // Uniform grid over the rows for the neighbourhood search (cell = reach_).
  std::vector<std::pair<std::uint64_t, std::uint32_t>> row_grid_;
};

/// How a single shot samples its rows' whole footprints (PlannerSettings::footprint_samples): on a cell, and in
/// free space under FreeSpaceGuard::kFootprintSamples (a noise-free rough model).
struct WholeRowSampling {
  std::size_t max_samples = 1;  // per row, at most
  /// One sample per this much of a row's area (mm²); a row under two samples' worth is left to its vertex.
  /// 0: every row max_samples.
  double sample_area_mm2 = 0.0;
  std::vector<std::uint32_t> crease;  // rows sampled whatever their area (crease_rows), ascending
  std::size_t crease_samples = 0;     // those rows' samples (at least; 0: crease rows as any other)
};

/// Rows' whole footprints (nothing measured yet), as a single shot predicts rows by
/// (PlannerSettings::footprint_samples): MeasuredCoverage(rough, spec, options).open_footprints of every
/// row that `s` gives two samples or more, each with its count.
RowFootprints whole_row_footprints(const RoughModel& rough, const ModelSpec& spec, const WholeRowSampling& s, CoverageOptions options = {});

}  // namespace scancell::planner
