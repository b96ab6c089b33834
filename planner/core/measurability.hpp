#pragma once
#include <atomic>
// The measurability matrix M (thesis 3.3): rows are rough-model points, columns candidate viewpoints;
// m_ij = 1 when point i lies in viewpoint j's frustum, is visible to both laser and receiver, and its
// predicted precision (eq. 3.4) and sampling density (eq. 3.8) meet the model specification.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "planner/core/rough_model.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

/// One column, stored as a sorted row list or as a bitset over all rows, whichever is smaller.
class MeasurabilityColumn {
 public:
  MeasurabilityColumn() = default;
  MeasurabilityColumn(std::vector<std::uint32_t> sorted_rows, std::uint32_t n_rows);

  std::uint32_t count() const { return count_; }
  bool is_bitset() const { return !bits_.empty(); }
  bool contains(std::uint32_t row) const;
  std::size_t memory_bytes() const { return rows_.capacity() * 4 + bits_.capacity() * 8; }

  template <class F>
  void for_each(F&& f) const {
    if (bits_.empty()) {
      for (auto r : rows_) f(r);
      return;
    }
    for (std::size_t w = 0; w < bits_.size(); ++w) {
      std::uint64_t b = bits_[w];
      while (b) {
        const int t = __builtin_ctzll(b);
        f(static_cast<std::uint32_t>(w * 64 + t));
        b &= b - 1;
      }
    }
  }
  std::vector<std::uint32_t> rows() const;

 private:
  std::vector<std::uint32_t> rows_;
  std::vector<std::uint64_t> bits_;
  std::uint32_t count_ = 0;
};

struct OverlapRows;

struct MeasurabilityMatrix {
  std::uint32_t n_rows = 0;
  std::vector<MeasurabilityColumn> columns;
  /// What the registration constraint (eq. 4.1-4.2) judges two columns' overlap by, when not by these rows
  /// and the cover's weights: the same columns over other rows (a cover by footprint samples shares a row
  /// between two views when each measures some of its samples: footprint.hpp). Null: these rows.
  std::shared_ptr<const OverlapRows> overlap;

  std::size_t n_cols() const { return columns.size(); }
  std::size_t nonzeros() const;
  double density() const;  // nonzeros / (rows × cols)
  std::size_t memory_bytes() const;
  /// Rows no column measures.
  std::vector<std::uint32_t> unmeasurable_rows() const;
};

/// The rows and weights two columns' registration overlap is counted in (MeasurabilityMatrix::overlap).
struct OverlapRows {
  MeasurabilityMatrix matrix;  // one column per column of the matrix it belongs to; no overlap of its own
  std::vector<double> weight;  // per row of `matrix`
};

struct MatrixStats {
  std::uint64_t pairs_total = 0;        // rows × columns
  std::uint64_t pairs_block_culled = 0; // skipped with their whole block (bounding sphere outside the frustum)
  std::uint64_t pairs_normal_culled = 0;  // skipped with their whole block (its normal cone faces away from the camera)
  std::uint64_t pairs_in_frustum = 0;
  std::uint64_t pairs_surviving = 0;    // in frustum and facing both laser and receiver
  std::uint64_t pairs_compliant = 0;    // ... and meeting thresholds, precision, density: these cast rays
  std::uint64_t rays_cast = 0;
  std::uint64_t pairs_measurable = 0;
};

/// Measurability countermeasures against positioner pose error (thesis 7.4.7): detuned tests that leave a
/// margin, sized from tables 7.3-7.5 (pose_error.hpp: countermeasures_for).
struct Countermeasures {
  double frustum_detune = 0.0;       // shrink the frustum's width and the sweep length by this fraction
  double dof_margin_mm = 0.0;        // raise R_min and lower R_max by this much
  double compliance_buffer = 0.0;    // require σz ≤ spec/(1 + b) and ρ ≥ spec·(1 + b)
  double visibility_margin_mm = 0.0; // near-miss visibility: laser and receiver displaced by ± this in camera
                                     // x and y must see the point too
  bool any() const { return frustum_detune > 0 || dof_margin_mm > 0 || compliance_buffer > 0 || visibility_margin_mm > 0; }
};

/// The sensor and specification the detuned tests use (depth of field shrunk, spec tightened); the frustum's
/// width and sweep length are narrowed by the matrix builder itself (the sample spacing does not change).
SensorModel detuned_sensor(const SensorModel& sensor, const Countermeasures& c);
ModelSpec detuned_spec(const ModelSpec& spec, const Countermeasures& c);

/// The compliance margin open-direction views' columns claim rows with (thesis 7.4.7): they work far out, near
/// the precision and density limits, where the rough model's averaged normals mislead most (docs/planner.md).
inline constexpr double kOpenDirectionComplianceMargin = 0.1;

/// The countermeasures those columns claim rows with (every row on a rough model with noise; on a noise-free
/// one the rows nothing else measures: plan.cpp, make_matrix), under a matrix whose own are `matrix_cm`: its
/// compliance buffer topped up to the margin, or nothing when it already holds that much. The
/// free-space margin holds every column to σz ≤ spec/1.1; stacked on it, these views were held to spec/1.21 and
/// left rows to other views (couplingdown in free space 212 -> 198 views, m_v of the reach 0.9943 -> 0.9949;
/// docs/quality.md).
std::optional<Countermeasures> open_direction_margin(const Countermeasures& matrix_cm);

struct MatrixSettings {
  /// Occlusion rays start this far off the surface along the normal, and stop this short of the sensor.
  /// Zero means: 1 % of the rough model's mean edge length.
  double ray_offset_mm = 0.0;
  Countermeasures countermeasures;  // none by default
};

/// The occlusion rays' offset off the surface `st` gives for `rough` (MatrixSettings::ray_offset_mm), in mm.
double ray_offset_mm(const RoughModel& rough, const MatrixSettings& st);

/// The elements a plainer test gives (e.g. without the free-space margin), built in the same pass as the matrix:
/// `matrix` holds, per column, the rows the plain test measures and the matrix's test does not.
struct PlainElements {
  Countermeasures countermeasures;  // each at most the matrix's own
  MeasurabilityMatrix matrix;       // filled by build_measurability
  /// One flag per row: only the flagged rows' plain elements are wanted (the others' rays are not cast). Null:
  /// every row's.
  const std::vector<std::uint8_t>* rows = nullptr;
};

/// Per column j, the only rows worth testing (ascending, appended to `rows`); the others are not measurable by
/// the caller's own knowledge. Called concurrently for different columns.
using RowsToTest = std::function<void(std::size_t column, std::vector<std::uint32_t>& rows)>;

/// Builds M in parallel over candidates (oneTBB). Rows are visited in the rough model's Morton order, blocks of
/// rows are culled by bounding sphere, single points by frustum, facing and specification before any ray, and
/// the surviving pairs' two occlusion rays are streamed through Embree (a near-miss margin's eight more only
/// for the pairs those two leave clear). Deterministic for any thread count. With `plain`, the plain test's
/// extra elements too, at the cost of the rays only they need. With `only`, each column tests just the rows it
/// names (no block culling; the rest count as culled).
MeasurabilityMatrix build_measurability(const RoughModel& rough, const OcclusionScene& scene, const SensorModel& sensor,
                                        const ModelSpec& spec, const std::vector<Viewpoint>& candidates,
                                        const MatrixSettings& settings = {}, MatrixStats* stats = nullptr,
                                        const std::atomic<int>* cancel = nullptr, PlainElements* plain = nullptr,
                                        const RowsToTest* only = nullptr);

/// The free-space margin chooses among the views that can measure a row; it does not give up a row only views
/// at the edge of the spec reach measure (a bore's wall, seen only at grazing incidence): the rows `m` measures
/// in no column get the elements `plain` (built in the same pass) gives them. Returns how many rows did.
std::size_t keep_plain_elements_of_lost_rows(MeasurabilityMatrix& m, const PlainElements& plain);

/// The same element test with no culling at all: every pair is transformed and both rays cast whatever the
/// analytic tests say. The thesis' O(s²v) reference; for benchmarks and cross-checks only.
MeasurabilityMatrix build_measurability_naive(const RoughModel& rough, const OcclusionScene& scene,
                                              const SensorModel& sensor, const ModelSpec& spec,
                                              const std::vector<Viewpoint>& candidates, const MatrixSettings& settings = {},
                                              MatrixStats* stats = nullptr);

/// m_ij for a single pair (same test as the builders), for tests and diagnostics.
bool measurable(const RoughModel& rough, const OcclusionScene& scene, const SensorModel& sensor, const ModelSpec& spec,
                const Viewpoint& view, std::uint32_t row, const MatrixSettings& settings = {});

}  // namespace scancell::planner
