// Exact set covering on CBC: known optima (one where greedy is provably suboptimal), the registration
// constraint, infeasible inputs, presolve, and the anytime time limit.
#include <chrono>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "planner/core/exact_cover.hpp"

namespace sp = scancell::planner;

namespace {

sp::MeasurabilityMatrix matrix(std::uint32_t rows, const std::vector<std::vector<std::uint32_t>>& cols) {
  sp::MeasurabilityMatrix m;
  m.n_rows = rows;
  for (auto c : cols) {
    std::sort(c.begin(), c.end());
    m.columns.emplace_back(c, rows);
  }
  return m;
}

std::vector<std::uint32_t> range(std::uint32_t a, std::uint32_t b) {  // [a, b)
  std::vector<std::uint32_t> v(b - a);
  std::iota(v.begin(), v.end(), a);
  return v;
}

std::vector<std::uint32_t> concat(std::vector<std::uint32_t> a, const std::vector<std::uint32_t>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

sp::CoverSettings exact(double t_r = 0.0, double seconds = 10.0) {
  sp::CoverSettings s;
  s.mode = sp::CoverMode::exact;
  s.registration_threshold = t_r;
  s.exact_time_limit_s = seconds;
  return s;
}

bool covers(const sp::MeasurabilityMatrix& m, const std::vector<std::uint32_t>& views) {
  std::vector<char> cov(m.n_rows, 0);
  for (auto j : views) m.columns[j].for_each([&](std::uint32_t r) { cov[r] = 1; });
  for (auto r : m.unmeasurable_rows()) cov[r] = 1;
  return std::all_of(cov.begin(), cov.end(), [](char c) { return c; });
}

}  // namespace

TEST(ExactCover, FindsTheOptimumWhereGreedyIsProvablySuboptimal) {
  // Two halves T = rows 0-6 and B = rows 7-13 (columns 0 and 1). Columns 2-4 take 4+4, 2+2 and 1+1 rows of
  // the halves: greedy takes 8 > 7, then 4 > 3, then 2 > 1, and each keeps a row of its own, so neither
  // greedy nor redundancy elimination gets below 3. The optimum is {T, B}.
  const auto m = matrix(14, {range(0, 7), range(7, 14), concat(range(0, 4), range(7, 11)), {4, 5, 11, 12}, {6, 13}});
  const std::vector<double> w(14, 1.0);
  sp::CoverSettings g = exact();
  g.mode = sp::CoverMode::greedy;
  EXPECT_EQ(sp::greedy_cover(m, w, g).views.size(), 3u);
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, w, exact(), {}, &rep);
  EXPECT_EQ(r.views.size(), 2u);
  EXPECT_TRUE(covers(m, r.views));
  EXPECT_TRUE(rep.proven_optimal) << rep.status;
  EXPECT_EQ(rep.objective, 2.0);
  EXPECT_EQ(rep.bound, 2.0);
  EXPECT_EQ(rep.gap, 0.0);
  EXPECT_EQ(rep.greedy_objective, 3.0);
  EXPECT_NEAR(r.cumulative_fraction.back(), 1.0, 1e-12);
}

TEST(ExactCover, RowsGreedyLeavesUnderTheMinimumGainStayOpenAndGreedyWarmStarts) {
  // The instance above plus row 14 of weight 0.5, which only column 5 sees. With cover.min_view_gain 1 greedy
  // never spends a view on it (3 views, row 14 open). Exact cover leaves it open too: greedy's 3 views are a
  // feasible warm start (objective 3, not 0) and the optimum is {T, B}, not {T, B, 5}.
  const auto m =
      matrix(15, {range(0, 7), range(7, 14), concat(range(0, 4), range(7, 11)), {4, 5, 11, 12}, {6, 13}, {14}});
  std::vector<double> w(15, 1.0);
  w[14] = 0.5;
  sp::CoverSettings s = exact();
  s.min_view_gain = 1.0;
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, w, s, {}, &rep);
  EXPECT_EQ(rep.rows_below_min_gain, 1u);
  EXPECT_EQ(rep.rows, 14u);
  EXPECT_EQ(rep.greedy_objective, 3.0);
  EXPECT_EQ(r.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_TRUE(rep.proven_optimal) << rep.status;
  EXPECT_NE(r.stop_reason.find("1 rows left open"), std::string::npos) << r.stop_reason;
  EXPECT_NEAR(r.cumulative_fraction.back(), 14.0 / 14.5, 1e-12);
}

TEST(ExactCover, ACheaperFeasibleStartReplacesGreedyAndOthersAreIgnored) {
  // The instance greedy provably needs 3 views for. Started from the optimum {T, B} (what the plan's local
  // search hands over), that is the warm start and the answer of record: CBC finds nothing better and proves it.
  const auto m = matrix(14, {range(0, 7), range(7, 14), concat(range(0, 4), range(7, 11)), {4, 5, 11, 12}, {6, 13}});
  const std::vector<double> w(14, 1.0);
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, w, exact(), {}, &rep, {1, 0});
  EXPECT_EQ(rep.greedy_objective, 3.0);
  EXPECT_EQ(rep.start_objective, 2.0);
  EXPECT_EQ(rep.improved_solutions, 0u);
  EXPECT_EQ(r.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_TRUE(rep.proven_optimal) << rep.status;
  // A start that leaves rows 7-13 open is no cover: greedy stays the warm start.
  sp::ExactReport open_rep;
  EXPECT_EQ(sp::exact_cover(m, w, exact(), {}, &open_rep, {0}).views.size(), 2u);
  EXPECT_EQ(open_rep.start_objective, 0.0);
  // Under the registration constraint a start whose views do not overlap is no answer either: A and B of the
  // instance below share nothing, and the connected optimum needs C.
  const auto reg = matrix(10, {range(0, 5), range(5, 10), range(3, 7), {0, 9}});
  sp::ExactReport reg_rep;
  EXPECT_EQ(sp::exact_cover(reg, std::vector<double>(10, 1.0), exact(0.3), {}, &reg_rep, {0, 1}).views.size(), 3u);
  EXPECT_EQ(reg_rep.start_objective, 0.0);
  EXPECT_THROW(sp::exact_cover(m, w, exact(), {}, nullptr, {0, 5}), std::invalid_argument);
}

TEST(ExactCover, TheCallersGreedyIsUsedAsGivenNotRunAgain) {
  // plan.cpp hands over the greedy cover it improved into the start. Given a greedy of columns 2, 3, 4, 0 (the
  // greedy cover plus T, which a rerun under exact_greedy_settings would never return: redundancy elimination
  // drops it), its cost 4 is what exact cover reports as greedy's, and CBC still proves {T, B}.
  const auto m = matrix(14, {range(0, 7), range(7, 14), concat(range(0, 4), range(7, 11)), {4, 5, 11, 12}, {6, 13}});
  const std::vector<double> w(14, 1.0);
  const auto own = sp::greedy_cover(m, w, sp::exact_greedy_settings(exact()));
  EXPECT_EQ(own.views.size(), 3u);
  sp::CoverResult given = own;
  given.views.push_back(0);
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, w, exact(), {}, &rep, {}, &given);
  EXPECT_EQ(rep.greedy_objective, 4.0);
  EXPECT_EQ(r.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_TRUE(rep.proven_optimal) << rep.status;
  // Without it, exact cover runs the same greedy itself: 3.
  sp::ExactReport own_rep;
  sp::exact_cover(m, w, exact(), {}, &own_rep);
  EXPECT_EQ(own_rep.greedy_objective, 3.0);
  // A handed-over greedy naming a column the matrix lacks is refused, naming it.
  given.views.push_back(7);
  try {
    sp::exact_cover(m, w, exact(), {}, nullptr, {}, &given);
    ADD_FAILURE() << "column 7 of 5 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("greedy column 7 of 5"), std::string::npos) << e.what();
  }
}

TEST(ExactCover, OverlapCountedInOtherRowsConnectsTheCover) {
  // The registration instance below (A = rows 0-4, B = rows 5-9, C = rows 3-6 bridging them, D = {0, 9}): by
  // its own rows the connected optimum is {A, B, C}. As a cover by footprint samples whose overlap is counted
  // in rough-model rows (MeasurabilityMatrix::overlap), A and B both measure samples of overlap row 0, so
  // σ(A, B) = 1 / min(1, 1) ≥ t_r and {A, B} is connected: 2 views, found by CBC in its worker process, which
  // gets the overlap rows with the problem.
  auto m = matrix(10, {range(0, 5), range(5, 10), range(3, 7), {0, 9}});
  const std::vector<double> w(10, 1.0);
  auto o = std::make_shared<sp::OverlapRows>();
  o->matrix = matrix(2, {{0}, {0}, {1}, {1}});
  o->weight = {1.0, 1.0};
  m.overlap = o;
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, w, exact(0.3), {}, &rep);
  EXPECT_EQ(r.views, (std::vector<std::uint32_t>{0, 1})) << rep.status;
  EXPECT_EQ(r.registration_components, 1u);
  EXPECT_TRUE(rep.proven_optimal) << rep.status;
  m.overlap = nullptr;
  EXPECT_EQ(sp::exact_cover(m, w, exact(0.3)).views.size(), 3u);
}

TEST(ExactCover, CostsChangeTheOptimum) {
  // Same instance, but T and B cost 5 each: the three greedy columns (cost 1) are now optimal.
  const auto m = matrix(14, {range(0, 7), range(7, 14), concat(range(0, 4), range(7, 11)), {4, 5, 11, 12}, {6, 13}});
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, std::vector<double>(14, 1.0), exact(), {5, 5, 1, 1, 1}, &rep);
  EXPECT_EQ(r.views.size(), 3u);
  EXPECT_EQ(rep.objective, 3.0);
  EXPECT_TRUE(rep.proven_optimal);
}

TEST(ExactCover, RegistrationMakesTheDisconnectedOptimumConnected) {
  // A = rows 0-4 and B = rows 5-9 cover everything but share nothing. C = rows 3-6 overlaps each by 2 of its
  // 4 rows (σ = 0.5 over the smaller view). Unconstrained optimum {A, B} (2); connected optimum {A, B, C} (3).
  const auto m = matrix(10, {range(0, 5), range(5, 10), range(3, 7), {0, 9}});
  const std::vector<double> w(10, 1.0);
  sp::ExactReport free_rep, reg_rep;
  EXPECT_EQ(sp::exact_cover(m, w, exact(0.0), {}, &free_rep).views.size(), 2u);
  const auto r = sp::exact_cover(m, w, exact(0.3), {}, &reg_rep);
  ASSERT_EQ(r.views.size(), 3u) << reg_rep.status;
  EXPECT_EQ(r.registration_components, 1u);
  EXPECT_TRUE(covers(m, r.views));
  EXPECT_TRUE(reg_rep.proven_optimal) << reg_rep.status;
  EXPECT_EQ(reg_rep.objective, 3.0);
  EXPECT_GE(reg_rep.connectivity_cuts + (reg_rep.solves == 1 ? 1 : 0), 1u);
}

TEST(ExactCover, ImpossibleRegistrationIsReportedNotHung) {
  // With t_r = 0.9 nothing overlaps enough: no connected cover exists.
  const auto m = matrix(10, {range(0, 5), range(5, 10), range(3, 7)});
  sp::ExactReport rep;
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = sp::exact_cover(m, std::vector<double>(10, 1.0), exact(0.9, 20.0), {}, &rep);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 15.0);
  EXPECT_EQ(rep.status.rfind("infeasible", 0), 0u) << rep.status;
  EXPECT_NE(r.stop_reason.find("infeasible"), std::string::npos);
  EXPECT_FALSE(rep.proven_optimal);
}

TEST(ExactCover, TheMaxViewNormalizerDividesByTheLargestView) {
  // A = rows 0-4, B = rows 5-9, C = rows 3-6, D = {0, 9}. C shares 2 rows with A and with B: σ = 2 / min(5, 4)
  // = 0.5 over the smaller view, 2 / 5 = 0.4 over the largest view (m_S, eq. 4.1). At t_r = 0.45 {A, B, C} is
  // connected by the first and by nothing under the second: no connected cover exists.
  const auto m = matrix(10, {range(0, 5), range(5, 10), range(3, 7), {0, 9}});
  const std::vector<double> w(10, 1.0);
  sp::CoverSettings smaller = exact(0.45);
  smaller.normalizer = sp::RegistrationNormalizer::smaller_view;
  EXPECT_EQ(sp::exact_cover(m, w, smaller).views.size(), 3u);
  sp::CoverSettings largest = exact(0.45);
  largest.normalizer = sp::RegistrationNormalizer::max_view;
  sp::ExactReport rep;
  sp::exact_cover(m, w, largest, {}, &rep);
  EXPECT_EQ(rep.status.rfind("infeasible", 0), 0u) << rep.status;
  largest.registration_threshold = 0.4;
  EXPECT_EQ(sp::exact_cover(m, w, largest).registration_components, 1u);
}

TEST(ExactCover, RowsNobodyCoversAreExcludedAndReported) {
  const auto m = matrix(6, {{0, 1}, {1, 2}, {2, 3}, {0, 3}});  // rows 4 and 5: no column
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, std::vector<double>(6, 1.0), exact(), {}, &rep);
  EXPECT_EQ(r.unmeasurable_rows, (std::vector<std::uint32_t>{4, 5}));
  EXPECT_EQ(rep.rows, 4u);
  EXPECT_EQ(r.views.size(), 2u);  // {0,1}+{2,3} or {1,2}+{0,3}
  EXPECT_TRUE(covers(m, r.views));
  EXPECT_NEAR(r.measurable_fraction, 4.0 / 6.0, 1e-12);
}

TEST(ExactCover, PresolveForcesMergesAndDropsDominated) {
  // Row 0 has only column 0: forced, taking rows 0 and 1. Rows 2 and 3 are then both covered by {1, 2}:
  // merged. Row 4 ({1, 2, 3}) contains row 2's columns: dominated. Column 2 covers exactly what column 1
  // covers at the same cost: dropped, which leaves row 2 with column 1 alone: forced in the next round.
  // Nothing is left for the solver, and the optimum {0, 1} is proven by presolve alone.
  const auto m = matrix(5, {{0, 1}, {1, 2, 3, 4}, {2, 3, 4}, {4}});
  sp::ExactReport rep;
  const auto r = sp::exact_cover(m, std::vector<double>(5, 1.0), exact(), {}, &rep);
  EXPECT_EQ(rep.forced_columns, 2u);
  EXPECT_EQ(rep.merged_rows, 1u);
  EXPECT_EQ(rep.dominated_rows, 1u);
  EXPECT_EQ(rep.dominated_columns, 1u);
  EXPECT_EQ(rep.rows_after_presolve, 0u);
  EXPECT_EQ(r.views.size(), 2u);
  EXPECT_TRUE(rep.proven_optimal);
  EXPECT_EQ(rep.solves, 0u);
}

TEST(ExactCover, TimeLimitReturnsTheBestCoverWithItsGap) {
  // Random 300 × 300 at density 0.5: far from provable in 1 s. The answer comes back near the limit, is a
  // cover, is no worse than greedy, and carries a bound below it.
  std::mt19937 rng(5);
  std::bernoulli_distribution coin(0.5);
  std::vector<std::vector<std::uint32_t>> cols(300);
  for (auto& c : cols)
    for (std::uint32_t r = 0; r < 300; ++r)
      if (coin(rng)) c.push_back(r);
  const auto m = matrix(300, cols);
  sp::ExactReport rep;
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = sp::exact_cover(m, std::vector<double>(300, 1.0), exact(0.0, 1.0), {}, &rep);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took, 4.0);  // the limit plus the kill grace, with room for a loaded machine
  EXPECT_TRUE(covers(m, r.views));
  EXPECT_LE(rep.objective, rep.greedy_objective);
  EXPECT_GT(rep.bound, 0.0);
  EXPECT_LE(rep.bound, rep.objective);
  EXPECT_NEAR(rep.gap, (rep.objective - rep.bound) / rep.objective, 1e-12);
}

TEST(Cover, RedundancyEliminationDropsViewsOthersCover) {
  // Greedy takes the big middle column M = rows 2-7 first, then the ends L = 0-4 and R = 5-9, which
  // together cover M.
  const auto m = matrix(10, {range(0, 5), range(5, 10), range(2, 8)});
  sp::CoverSettings s;
  s.mode = sp::CoverMode::greedy;
  s.eliminate_redundant = false;
  const auto plain = sp::greedy_cover(m, std::vector<double>(10, 1.0), s);
  EXPECT_EQ(plain.views, (std::vector<std::uint32_t>{2, 0, 1}));
  s.eliminate_redundant = true;
  const auto lean = sp::greedy_cover(m, std::vector<double>(10, 1.0), s);
  EXPECT_EQ(lean.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_EQ(lean.redundant_removed, 1u);
  EXPECT_NEAR(lean.cumulative_fraction.back(), 1.0, 1e-12);
  // With the registration constraint M is the only link between L and R: it stays.
  s.mode = sp::CoverMode::constrained;
  s.registration_threshold = 0.3;
  const auto linked = sp::greedy_cover(m, std::vector<double>(10, 1.0), s);
  EXPECT_EQ(linked.views.size(), 3u);
  EXPECT_EQ(linked.registration_components, 1u);
}
