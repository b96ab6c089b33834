#pragma once
// Exact set covering (thesis eq. 4.7-4.10) on COIN-OR CBC: minimise Σ c_j x_j subject to every measurable row
// covered, with the registration constraint (eq. 4.6/4.9) enforced by lazily added connectivity cuts.
//
// - Presolve: rows no candidate measures are excluded (and reported); columns that are a row's only cover are
//   forced; identical rows are merged; a row whose columns include another row's is dropped (covering the
//   smaller covers it); without the registration constraint a column whose rows another column of no higher
//   cost covers is dropped (with it, a dominated column may still be the only bridge, so it stays).
// - Registration: the overlap graph of a cover (σ ≥ t_r) must be connected. A solution whose graph splits
//   into components is cut off by, for a component C, a chosen a ∈ C and a chosen b outside it:
//   Σ_{k ∈ N(C) \ C} x_k ≥ x_a + x_b − 1 (some neighbour of C must join when both sides are chosen), then
//   the program is solved again. The cuts are valid for every connected cover, so each solve's bound is a
//   bound of the constrained problem.
// - Bound: a Lagrangian (subgradient) bound on the row constraints is computed first (a quarter of the time
//   limit at most, 2 s at most); CBC's bound replaces it when better.
// - Core: above 300k nonzeros CBC gets a core problem (per row the 6 columns of least Lagrangian reduced
//   cost, plus the warm start), whose covers are covers of the whole; the Lagrangian bound stays the bound.
// - Anytime: CBC runs in a forked worker that streams every feasible cover and bound it finds; at the time
//   limit the worker is killed, whatever phase it is in (CBC does not honour its limit inside the root LP).
//   The greedy cover (redundancy-eliminated), or the caller's start when cheaper, is the warm start and the
//   answer of record, so exact mode is never worse than either.
#include <string>
#include <vector>

#include "planner/core/cover.hpp"

namespace scancell::planner {

struct ExactReport {
  std::string solver;             // "CBC <version>"
  std::string status;             // optimal | time limit | infeasible: why | greedy kept: why | start kept: why
  double objective = 0.0;         // Σ c_j of the returned cover
  double bound = 0.0;             // proven lower bound on the optimum
  double lagrangian_bound = 0.0;  // the subgradient (Lagrangian) bound computed before CBC starts
  double gap = 0.0;               // (objective − bound) / objective
  double greedy_objective = 0.0;  // greedy's cost (0 when greedy could not cover every row)
  double start_objective = 0.0;   // the caller's start cover's cost when it was the warm start (0: greedy was)
  double seconds = 0.0;
  std::size_t rows = 0, rows_after_presolve = 0;
  std::size_t rows_below_min_gain = 0;  // coverable rows left open as greedy leaves them (cover.min_view_gain_mm2)
  std::size_t columns = 0, columns_after_presolve = 0;
  std::size_t forced_columns = 0, merged_rows = 0, dominated_rows = 0, dominated_columns = 0;
  bool dominance_budget_hit = false;  // presolve stopped dominance checks to bound its own time
  std::size_t connectivity_cuts = 0, solves = 0, improved_solutions = 0;
  std::size_t core_columns = 0;       // > 0: CBC saw only this core of the columns (large instances)
  bool proven_optimal = false;
};

/// The settings of the greedy cover exact_cover warms from: constrained when registration applies, coverage
/// goal 1, redundant views eliminated.
CoverSettings exact_greedy_settings(const CoverSettings& settings);

/// `column_cost`: one positive cost per column (expected move time, ...), or empty for c_j = 1. `start`: a
/// cover to start from (the local search's), the warm start and answer of record instead of greedy's when it
/// covers every row greedy's does, registers and costs less; otherwise ignored. `greedy`: greedy_cover of this
/// matrix under exact_greedy_settings(settings) when the caller has it already (plan.cpp, which improves it to
/// make `start`); otherwise it is computed here. The result's views are ordered as greedy would take them; its
/// stop_reason names the solver outcome. Throws ConfigError when the settings' coverage goal is below 1 (the
/// program covers every measurable row).
CoverResult exact_cover(const MeasurabilityMatrix& m, const std::vector<double>& row_weight,
                        const CoverSettings& settings, const std::vector<double>& column_cost = {},
                        ExactReport* report = nullptr, const std::vector<std::uint32_t>& start = {},
                        const CoverResult* greedy = nullptr);

}  // namespace scancell::planner
