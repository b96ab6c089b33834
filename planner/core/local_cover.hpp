#pragma once
// Fewer views than greedy: weighted local search for unicost set cover (thesis ch. 4 poses the plan as a set
// cover, eq. 4.7-4.10; greedy is within ln(n) of the optimum and on whole objects typically 10-25 % above it).
//
// The search follows RWLS (row weighting local search, Gao et al. 2015): starting from a cover (constrained
// greedy's), it removes a view whenever the set covers every row, and otherwise swaps: the view whose removal
// uncovers the least row weight leaves, the best view for a random uncovered row enters, and every row left
// uncovered gains weight, so rows that are hard to cover pull the search towards views that cover them. A
// view just removed may not re-enter and a view just added may not leave on the next step (tabu); ties go to
// the view that has waited longest, then to the lower column index.
//
// Registration (eq. 4.2, 4.6): every smaller cover the search finds is checked; when its overlap graph
// (σ ≥ t_r) splits, bridge views that overlap two components by t_r are added (most components joined first)
// and the repaired cover is kept only if it is still smaller than the best so far. So the result is a
// registered cover whenever the start was, and never larger than the start.
//
// Deterministic for a seed: the budget is a count of swaps and of matrix elements visited since the last
// smaller cover; the wall-clock limit is a safety cap, and when it cuts the search the report says so (only
// then may the result depend on the machine).
#include <cstdint>
#include <string>
#include <vector>

#include "planner/core/cover.hpp"

namespace scancell::planner {

struct LocalSearchReport {
  std::size_t start_views = 0;
  std::size_t best_views = 0;
  std::uint64_t iterations = 0;     // swaps done
  std::size_t improvements = 0;     // smaller registered covers found
  std::uint64_t last_improvement_iteration = 0;  // the swap count when the best cover was found
  std::uint64_t work = 0;                        // elements visited (Search::work)
  std::uint64_t work_at_last_improvement = 0;
  std::size_t rejected_unregistered = 0;  // smaller covers whose repair was not smaller than the best
  double seconds = 0.0;
  bool time_limit_hit = false;
};

/// A cover of the rows `start` covers (those of positive weight), with at most as many views, registered
/// under the settings when registration applies. `iterations` swaps at most, and no more than
/// `settings.local_search_stall_work` matrix elements visited after the last smaller cover; `time_limit_s` at
/// most.
std::vector<std::uint32_t> local_search_cover(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                                              const CoverSettings& settings, const std::vector<std::uint32_t>& start,
                                              std::uint64_t iterations, double time_limit_s, std::uint64_t seed,
                                              LocalSearchReport* report = nullptr);

/// Connected components of the registration graph (σ ≥ t_r, eq. 4.2) of `views`; 1 for one view, 0 for none.
std::size_t registration_component_count(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                                         const CoverSettings& settings, const std::vector<std::uint32_t>& views);

}  // namespace scancell::planner
