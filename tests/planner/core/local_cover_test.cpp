// The local-search cover (local_cover.hpp): smaller than greedy where greedy is known to be trapped, optimal
// on small random instances whose optimum is found by enumeration, registered when registration applies,
// never larger than its start, and deterministic for a seed.
#include <algorithm>
#include <random>

#include <gtest/gtest.h>

#include "planner/core/cover.hpp"
#include "planner/core/local_cover.hpp"

namespace scancell::planner {
namespace {

MeasurabilityMatrix matrix(std::uint32_t rows, const std::vector<std::vector<std::uint32_t>>& cols) {
  MeasurabilityMatrix m;
  m.n_rows = rows;
  for (const auto& c : cols) m.columns.emplace_back(c, rows);
  return m;
}

/// 300 views of 5-34 rows each over 400 rows, strided runs (seeded): a cover greedy does not solve exactly.
MeasurabilityMatrix strided_instance(std::mt19937& rng, std::uint32_t rows = 400, std::uint32_t cols = 300) {
  std::vector<std::vector<std::uint32_t>> cs(cols);
  for (std::uint32_t j = 0; j < cols; ++j) {
    const std::uint32_t c = rng() % rows, len = 5 + rng() % 30;
    for (std::uint32_t k = 0; k < len; ++k) cs[j].push_back((c + k * (1 + j % 3)) % rows);
    std::sort(cs[j].begin(), cs[j].end());
    cs[j].erase(std::unique(cs[j].begin(), cs[j].end()), cs[j].end());
  }
  return matrix(rows, cs);
}

bool covers(const MeasurabilityMatrix& m, const std::vector<std::uint32_t>& views, const std::vector<std::uint32_t>& of) {
  std::vector<char> got(m.n_rows, 0);
  for (auto j : views) m.columns[j].for_each([&](std::uint32_t r) { got[r] = 1; });
  return std::all_of(of.begin(), of.end(), [&](std::uint32_t r) { return got[r] != 0; });
}

/// Greedy's trap: the big column {0,1,2,3} first, then both halves anyway; the two halves alone cover all.
TEST(LocalSearch, FindsTheTwoHalvesGreedyMisses) {
  const auto m = matrix(6, {{0, 1, 2, 3}, {0, 2, 4}, {1, 3, 5}});
  CoverSettings st;
  st.mode = CoverMode::greedy;
  st.eliminate_redundant = false;
  const std::vector<double> w(6, 1.0);
  const CoverResult g = greedy_cover(m, w, st);
  ASSERT_EQ(g.views, (std::vector<std::uint32_t>{0, 1, 2}));
  LocalSearchReport rep;
  auto best = local_search_cover(m, w, st, g.views, 1000, 10.0, 1, &rep);
  std::sort(best.begin(), best.end());
  EXPECT_EQ(best, (std::vector<std::uint32_t>{1, 2}));
  EXPECT_EQ(rep.start_views, 3u);
  EXPECT_EQ(rep.best_views, 2u);
  EXPECT_GE(rep.improvements, 1u);
}

/// The two halves share no row, so with the registration constraint (t_r > 0) they cannot be the plan: the
/// search must keep the column that overlaps both.
TEST(LocalSearch, KeepsTheOverlapRegistrationNeeds) {
  const auto m = matrix(6, {{0, 1, 2, 3}, {0, 2, 4}, {1, 3, 5}});
  CoverSettings st;
  st.mode = CoverMode::constrained;
  st.registration_threshold = 0.3;
  st.eliminate_redundant = false;
  const std::vector<double> w(6, 1.0);
  const CoverResult g = greedy_cover(m, w, st);
  ASSERT_EQ(g.views.size(), 3u);
  LocalSearchReport rep;
  const auto best = local_search_cover(m, w, st, g.views, 1000, 10.0, 1, &rep);
  EXPECT_EQ(best.size(), 3u);
  EXPECT_EQ(registration_component_count(m, w, st, best), 1u);
  EXPECT_GE(rep.rejected_unregistered, 1u);  // it found {1, 2} and refused it
}

/// The unregistered optimum {A, B} (disjoint halves) is found, refused, and the best registered cover keeps
/// both halves and one view overlapping each by t_r.
TEST(LocalSearch, SettlesOnTheSmallestRegisteredCoverWhenTheOptimumSplits) {
  // A = rows 0-3, B = rows 4-7; D, E, F each share one row with either half.
  const auto m = matrix(8, {{0, 1, 2, 3}, {4, 5, 6, 7}, {3, 4}, {0, 4}, {1, 5}});
  CoverSettings st;
  st.mode = CoverMode::constrained;
  st.registration_threshold = 0.2;
  const std::vector<double> w(8, 1.0);
  ASSERT_EQ(registration_component_count(m, w, st, {0, 1}), 2u);
  ASSERT_EQ(registration_component_count(m, w, st, {0, 1, 2, 3, 4}), 1u);
  LocalSearchReport rep;
  auto best = local_search_cover(m, w, st, {0, 1, 2, 3, 4}, 2000, 10.0, 3, &rep);
  std::sort(best.begin(), best.end());
  ASSERT_EQ(best.size(), 3u);
  EXPECT_EQ(best[0], 0u);
  EXPECT_EQ(best[1], 1u);
  EXPECT_TRUE(covers(m, best, {0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(registration_component_count(m, w, st, best), 1u);
  EXPECT_GE(rep.rejected_unregistered, 1u);
}

/// Random instances small enough to enumerate: the search reaches the optimum from greedy's cover.
TEST(LocalSearch, ReachesTheEnumeratedOptimumOnSmallRandomInstances) {
  std::mt19937 rng(11);
  int greedy_worse = 0;
  for (int inst = 0; inst < 25; ++inst) {
    const std::uint32_t rows = 30, cols = 14;
    std::vector<std::vector<std::uint32_t>> cs(cols);
    for (std::uint32_t r = 0; r < rows; ++r) {
      cs[rng() % cols].push_back(r);  // every row has a column
      for (std::uint32_t j = 0; j < cols; ++j)
        if (rng() % 5 == 0) cs[j].push_back(r);
    }
    for (auto& c : cs) {
      std::sort(c.begin(), c.end());
      c.erase(std::unique(c.begin(), c.end()), c.end());
    }
    const auto m = matrix(rows, cs);
    std::size_t optimum = cols;
    for (std::uint32_t mask = 1; mask < (1u << cols); ++mask) {
      const auto k = static_cast<std::size_t>(__builtin_popcount(mask));
      if (k >= optimum) continue;
      std::vector<std::uint32_t> v;
      for (std::uint32_t j = 0; j < cols; ++j)
        if (mask >> j & 1) v.push_back(j);
      std::vector<std::uint32_t> all(rows);
      for (std::uint32_t r = 0; r < rows; ++r) all[r] = r;
      if (covers(m, v, all)) optimum = k;
    }
    CoverSettings st;
    st.mode = CoverMode::greedy;
    const std::vector<double> w(rows, 1.0);
    const CoverResult g = greedy_cover(m, w, st);
    greedy_worse += g.views.size() > optimum;
    const auto best = local_search_cover(m, w, st, g.views, 5000, 10.0, 7);
    std::vector<std::uint32_t> all(rows);
    for (std::uint32_t r = 0; r < rows; ++r) all[r] = r;
    EXPECT_TRUE(covers(m, best, all)) << "instance " << inst;
    EXPECT_EQ(best.size(), optimum) << "instance " << inst << ": greedy " << g.views.size();
  }
  EXPECT_GE(greedy_worse, 3);  // the instances are not all easy for greedy
}

TEST(LocalSearch, SameSeedSameCoverAndNeverLargerThanItsStart) {
  std::mt19937 rng(5);
  const std::uint32_t rows = 400;
  const auto m = strided_instance(rng);
  std::vector<double> w(rows);
  for (auto& x : w) x = 0.5 + (rng() % 100) / 100.0;
  CoverSettings st;
  st.mode = CoverMode::constrained;
  const CoverResult g = greedy_cover(m, w, st);
  const auto a = local_search_cover(m, w, st, g.views, 3000, 60.0, 9);
  const auto b = local_search_cover(m, w, st, g.views, 3000, 60.0, 9);
  EXPECT_EQ(a, b);
  EXPECT_LE(a.size(), g.views.size());
  std::vector<std::uint32_t> wanted;
  std::vector<char> got(rows, 0);
  for (auto j : g.views) m.columns[j].for_each([&](std::uint32_t r) { got[r] = 1; });
  for (std::uint32_t r = 0; r < rows; ++r)
    if (got[r]) wanted.push_back(r);
  EXPECT_TRUE(covers(m, a, wanted));
  if (registration_component_count(m, w, st, g.views) == 1) {
    EXPECT_EQ(registration_component_count(m, w, st, a), 1u);
  }
}

/// The stall budget only cuts the same trajectory short: a search stopped once it visited `stall` elements
/// after its last smaller cover returns what a search with exactly that many swaps returns, and a start
/// that is already minimal stops after that much work, not the whole swap budget.
TEST(LocalSearch, StopsAStallBudgetAfterItsLastSmallerCover) {
  std::mt19937 rng(5);
  const std::uint32_t rows = 400;
  const auto m = strided_instance(rng);
  const std::vector<double> w(rows, 1.0);
  CoverSettings st;
  st.mode = CoverMode::greedy;
  const CoverResult g = greedy_cover(m, w, st);
  st.local_search_stall_work = 20000;
  LocalSearchReport cut;
  const auto a = local_search_cover(m, w, st, g.views, 100000, 60.0, 9, &cut);
  ASSERT_GE(cut.improvements, 1u);
  ASSERT_LT(cut.iterations, 100000u);  // stopped by the stall, not the swap budget
  EXPECT_GE(cut.work - cut.work_at_last_improvement, 20000u);
  st.local_search_stall_work = 1000000000000ULL;
  LocalSearchReport full;
  const auto b = local_search_cover(m, w, st, g.views, cut.iterations, 60.0, 9, &full);
  EXPECT_EQ(a, b);
  EXPECT_EQ(full.iterations, cut.iterations);
  EXPECT_EQ(full.last_improvement_iteration, cut.last_improvement_iteration);

  // Rows 0-1, 2-3 and 4-5 each need their own view (rows 0 and 5 have one column each, and no column holds
  // rows 2 and 3 with either): the start is minimal.
  const auto thirds = matrix(6, {{0, 1}, {2, 3}, {4, 5}, {1, 2}, {3, 4}});
  st.local_search_stall_work = 500;
  LocalSearchReport none;
  const auto c = local_search_cover(thirds, std::vector<double>(6, 1.0), st, {0, 1, 2}, 100000, 60.0, 1, &none);
  EXPECT_EQ(c.size(), 3u);
  EXPECT_EQ(none.improvements, 0u);
  EXPECT_GT(none.iterations, 10u);
  EXPECT_LT(none.iterations, 500u);  // a swap here visits at least a column of two rows
  EXPECT_GE(none.work - none.work_at_last_improvement, 500u);
}

}  // namespace
}  // namespace scancell::planner
