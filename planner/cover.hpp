#pragma once
// Set covering of the measurability matrix (thesis ch. 4): lazy greedy search (4.4.2) and greedy search with
// the image-based registration constraint (4.4.3), plus the registration graph of the chosen views (4.2.5).
#include <cstdint>
#include <string>
#include <vector>

#include "planner/measurability.hpp"

namespace scancell::planner {

enum class CoverMode { greedy, constrained };

/// What σ_kj (eq. 4.1) divides the shared weight by. The thesis uses m_S, the largest single view of all
/// candidates; on whole objects with views of very different size that makes small views (cavities, curved
/// edges) unregistrable to anything. `smaller_view` divides by the smaller of the two views instead: the
/// fraction of the smaller image that overlaps the other, still in [0, 1] and reciprocal.
enum class RegistrationNormalizer { max_view, smaller_view };

struct CoverSettings {
  CoverMode mode = CoverMode::constrained;
  double registration_threshold = 0.1;  // t_r: σ_kj ≥ t_r for two views to register (eq. 4.2)
  RegistrationNormalizer normalizer = RegistrationNormalizer::smaller_view;
  double coverage_goal = 1.0;           // stop once this fraction of the total row weight is covered
};

struct RegistrationEdge {
  std::uint32_t a, b;  // positions in the plan (selection order)
  double sigma;        // σ_ab, eq. 4.1 with row weights (see greedy_cover)
};

struct CoverResult {
  std::vector<std::uint32_t> views;              // column indices in selection order
  std::vector<double> gain_weight;               // weight newly covered by each view
  std::vector<double> cumulative_fraction;       // covered weight / total weight, after each view
  std::vector<double> cumulative_point_fraction; // covered rows / all rows, after each view
  std::vector<std::uint32_t> unmeasurable_rows;  // rows no candidate measures
  double measurable_fraction = 0.0;              // weight of rows some candidate measures / total
  std::vector<RegistrationEdge> registration_edges;  // σ ≥ t_r among the chosen views
  std::size_t registration_components = 0;      // connected components of the registration graph
  std::uint32_t max_column_count = 0;            // rows of the largest column
  double max_column_weight = 0.0;                // m_S, the normaliser of eq. 4.1, in row weight
  std::size_t blocked_by_registration = 0;       // times the best candidate had to wait for an overlap
  std::size_t bridge_views = 0;                  // views added only to let waiting candidates register
  std::string stop_reason;
};

/// σ_kj of eq. 4.1: shared rows of two columns over m_S.
double viewpoint_correlation(const MeasurabilityColumn& a, const MeasurabilityColumn& b, std::uint32_t m_s);

/// Total weight of the rows two columns share.
double shared_weight(const MeasurabilityColumn& a, const MeasurabilityColumn& b, const std::vector<double>& row_weight);

/// Greedy set cover with gain = newly covered row weight (use rough-model vertex areas for area-weighted
/// measurability, or all ones for the thesis' point count). Ties go to the lower column index, so the result
/// is deterministic. Self-terminating: stops when no candidate adds coverage or the goal is met. In
/// constrained mode every view after the first must reach σ ≥ t_r with at least one chosen view.
/// σ uses the same row weights as the gain: shared weight over the largest column's weight. With unit
/// weights that is eq. 4.1 exactly; with areas it keeps a decimated model (few rows on flat faces, many on
/// curved ones) from making the largest-area view unregistrable by row count.
CoverResult greedy_cover(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                         const CoverSettings& settings);

}  // namespace scancell::planner
