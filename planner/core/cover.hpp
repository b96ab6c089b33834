#pragma once
// Set covering of the measurability matrix (thesis ch. 4): lazy greedy search (4.4.2) and greedy search with
// the image-based registration constraint (4.4.3), plus the registration graph of the chosen views (4.2.5).
#include <cstdint>
#include <string>
#include <vector>

#include "planner/core/measurability.hpp"

namespace scancell::planner {

/// greedy: plain greedy search (4.4.2); constrained: greedy with the registration constraint (4.4.3); exact:
/// the integer program eq. 4.7-4.10 on CBC (exact_cover.hpp), registration enforced when t_r > 0.
enum class CoverMode { greedy, constrained, exact };

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
  /// After greedy: drop every view whose rows all other views cover too (latest first), keeping the
  /// registration graph connected when the registration constraint applies.
  bool eliminate_redundant = true;
  double exact_time_limit_s = 10.0;     // exact mode: wall-clock limit of the solver (anytime: best so far)
  /// Greedy stops when the best remaining view would newly cover less than this much row weight (mm² with
  /// area weights): the last views of a whole-object cover each chase a sliver the rough model promises and
  /// the fine surface often does not keep; the closed loop plans for what the executed views leave. 0: off.
  double min_view_gain = 0.0;
  /// greedy and constrained modes: swaps of the local search that then looks for a smaller cover
  /// (local_cover.hpp); 0 keeps greedy's cover. Deterministic: the budget is counted, not timed.
  std::uint64_t local_search_iterations = 0;
  /// The local search stops when it has visited this many matrix elements (column rows walked, score
  /// updates) since its last smaller cover: work counted, not timed, so deterministic, and scaled to the
  /// instance. A swap visits ~500-4,000 elements on 5k-row models (the default never stops them within
  /// 20,000 swaps) and 176k-431k on 26k-38k-row meshes as given, where 2e9 is 4,600-11,000 swaps, 1-2 s; the
  /// longest stretch between smaller covers seen there was 1.3e9.
  std::uint64_t local_search_stall_work = 2000000000ULL;
  double local_search_time_limit_s = 5.0;  // safety cap on the local search's wall-clock time
};

/// Whether the registration constraint applies: constrained greedy, or exact with t_r > 0.
inline bool registration_applies(const CoverSettings& s) {
  return s.mode == CoverMode::constrained || (s.mode == CoverMode::exact && s.registration_threshold > 0.0);
}

/// The cover for views that each register to the object's model, not to the views before them (a cell job's
/// rounds and setups: the daemon registers every scan to the model): constrained greedy becomes plain greedy,
/// as thesis 4.4.3's between-view constraint buys no registration there. `exact` is left as configured.
inline CoverSettings registered_to_model(CoverSettings s) {
  if (s.mode == CoverMode::constrained) s.mode = CoverMode::greedy;
  return s;
}

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
  std::size_t redundant_removed = 0;             // views dropped by the redundancy-elimination pass
  std::string stop_reason;
};

/// The columns and weights the registration constraint counts overlap in: the matrix's `overlap` when it has
/// one (checked: a column per column, a weight per row), else the matrix itself with the cover's weights.
struct OverlapView {
  const MeasurabilityMatrix& m;
  const std::vector<double>& w;
};
OverlapView overlap_of(const MeasurabilityMatrix& m, const std::vector<double>& row_weight);

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

/// σ_ab of eq. 4.1 under the settings' normaliser (shared row weight over the smaller view or over m_S).
double registration_sigma(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                          const CoverSettings& settings, std::uint32_t a, std::uint32_t b, double max_column_weight);

/// Views (in the given order) whose rows the others all cover, removed latest first; in constrained use the
/// registration graph of what remains must stay connected. Returns the kept views in their order.
std::vector<std::uint32_t> eliminate_redundant(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                                               const CoverSettings& settings, const std::vector<std::uint32_t>& views);

/// Orders a set of views as greedy would take them (largest new weight first; with the registration
/// constraint, among those that register with a view already ordered when any does).
std::vector<std::uint32_t> order_by_gain(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                                         const CoverSettings& settings, std::vector<std::uint32_t> views);

/// Fills a CoverResult for `views` taken in the given order: gains, cumulative fractions, unmeasurable rows,
/// m_S, registration edges and components. stop_reason and the greedy counters are left to the caller.
CoverResult describe_cover(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                           const CoverSettings& settings, const std::vector<std::uint32_t>& views);

}  // namespace scancell::planner
