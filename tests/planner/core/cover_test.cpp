// Set covering on small matrices whose optimal answers are known by hand.
#include <gtest/gtest.h>

#include "planner/core/cover.hpp"
#include "planner/core/exact_cover.hpp"
#include "planner/core/local_cover.hpp"

namespace scancell::planner {
namespace {

MeasurabilityMatrix matrix(std::uint32_t rows, const std::vector<std::vector<std::uint32_t>>& cols) {
  MeasurabilityMatrix m;
  m.n_rows = rows;
  for (const auto& c : cols) m.columns.emplace_back(c, rows);
  return m;
}

std::vector<double> ones(std::size_t n) { return std::vector<double>(n, 1.0); }

TEST(Column, StoresTheSmallerOfListAndBitset) {
  const MeasurabilityColumn sparse({3, 70, 900}, 1000);
  EXPECT_FALSE(sparse.is_bitset());
  std::vector<std::uint32_t> many;
  for (std::uint32_t r = 0; r < 1000; r += 2) many.push_back(r);
  const MeasurabilityColumn dense(many, 1000);
  EXPECT_TRUE(dense.is_bitset());
  EXPECT_EQ(dense.rows(), many);
  EXPECT_TRUE(dense.contains(998));
  EXPECT_FALSE(dense.contains(999));
  EXPECT_TRUE(sparse.contains(70));
  EXPECT_FALSE(sparse.contains(71));
  EXPECT_LT(dense.memory_bytes(), many.size() * 4);
}

TEST(Greedy, PicksLargestGainFirstAndStopsWhenNothingIsGained) {
  // Rows 0..5; row 5 no column measures.
  const auto m = matrix(6, {{0, 1}, {0, 1, 2, 3}, {3, 4}, {4}});
  CoverSettings st;
  st.mode = CoverMode::greedy;
  const CoverResult r = greedy_cover(m, ones(6), st);
  EXPECT_EQ(r.views, (std::vector<std::uint32_t>{1, 2}));
  EXPECT_EQ(r.unmeasurable_rows, (std::vector<std::uint32_t>{5}));
  EXPECT_NEAR(r.cumulative_fraction.back(), 5.0 / 6.0, 1e-12);
  EXPECT_NEAR(r.measurable_fraction, 5.0 / 6.0, 1e-12);
  EXPECT_EQ(r.stop_reason, "no candidate adds coverage");
}

TEST(Greedy, AreaWeightsChangeTheChoice) {
  const auto m = matrix(4, {{0, 1, 2}, {3}});
  CoverSettings st;
  st.mode = CoverMode::greedy;
  st.coverage_goal = 0.5;
  // By count column 0 wins; by area row 3 outweighs rows 0-2 together.
  EXPECT_EQ(greedy_cover(m, ones(4), st).views.front(), 0u);
  EXPECT_EQ(greedy_cover(m, {1, 1, 1, 10}, st).views.front(), 1u);
}

TEST(Greedy, TiesGoToTheLowerColumnIndex) {
  const auto m = matrix(4, {{0, 1}, {2, 3}, {0, 1}});
  CoverSettings st;
  st.mode = CoverMode::greedy;
  EXPECT_EQ(greedy_cover(m, ones(4), st).views, (std::vector<std::uint32_t>{0, 1}));
}

TEST(Constrained, EveryNewViewOverlapsAChosenView) {
  // 10 rows. Column 0 = rows 0-4 (m_S = 5). Column 1 = rows 5-9 covers the rest but shares nothing with 0.
  // Column 2 = rows 4-7 overlaps column 0 in one row (σ = 0.2) and column 3 = rows 7-9 overlaps column 2.
  const auto m = matrix(10, {{0, 1, 2, 3, 4}, {5, 6, 7, 8, 9}, {4, 5, 6, 7}, {7, 8, 9}});
  CoverSettings greedy;
  greedy.mode = CoverMode::greedy;
  const CoverResult g = greedy_cover(m, ones(10), greedy);
  EXPECT_EQ(g.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_EQ(g.registration_components, 2u);  // disconnected: σ_01 = 0

  CoverSettings con;
  con.mode = CoverMode::constrained;
  con.registration_threshold = 0.2;
  const CoverResult c = greedy_cover(m, ones(10), con);
  EXPECT_EQ(c.views, (std::vector<std::uint32_t>{0, 2, 1}));  // column 1 registers via column 2 (σ = 0.6)
  EXPECT_EQ(c.registration_components, 1u);
  EXPECT_DOUBLE_EQ(c.cumulative_fraction.back(), 1.0);
  EXPECT_GT(c.blocked_by_registration, 0u);
  ASSERT_FALSE(c.registration_edges.empty());
  EXPECT_NEAR(viewpoint_correlation(m.columns[0], m.columns[2], 5), 0.2, 1e-12);
}

TEST(Constrained, StopsWhenTheRestCannotRegister) {
  const auto m = matrix(6, {{0, 1, 2}, {3, 4, 5}});
  CoverSettings con;
  con.registration_threshold = 0.1;
  const CoverResult c = greedy_cover(m, ones(6), con);
  EXPECT_EQ(c.views.size(), 1u);
  EXPECT_EQ(c.stop_reason, "remaining gain needs views that cannot register (t_r)");
}

TEST(Constrained, ViewsRegisteredToTheModelCoverTheRestWithoutIt) {
  // The instance above, covered as a cell job covers it (registered_to_model): both halves, 2 views, where
  // the constraint stopped at 1. Exact covers keep their mode (and with t_r > 0 their registration).
  const auto m = matrix(6, {{0, 1, 2}, {3, 4, 5}});
  CoverSettings con;
  con.registration_threshold = 0.1;
  const CoverSettings job = registered_to_model(con);
  EXPECT_FALSE(registration_applies(job));
  EXPECT_EQ(greedy_cover(m, ones(6), job).views, (std::vector<std::uint32_t>{0, 1}));
  CoverSettings exact = con;
  exact.mode = CoverMode::exact;
  EXPECT_EQ(registered_to_model(exact).mode, CoverMode::exact);
  EXPECT_TRUE(registration_applies(registered_to_model(exact)));
}

TEST(Constrained, OverlapCountedInOtherRowsLetsTwoFacesRegister) {
  // The instance above as a cover by footprint samples sees a box's edge: rows 0-2 are samples on face A,
  // rows 3-5 on face B, and no view measures both faces, so their views share no sample and cannot register.
  // Counted in the rough model's rows (MeasurabilityMatrix::overlap: face A 4 mm², the edge row 1 mm², face B
  // 4 mm²) both views measure some of the edge row's samples: σ = 1 / min(5, 5) = 0.2 ≥ t_r, and the
  // constrained cover takes both.
  auto m = matrix(6, {{0, 1, 2}, {3, 4, 5}});
  auto o = std::make_shared<OverlapRows>();
  o->matrix = matrix(3, {{0, 1}, {1, 2}});
  o->weight = {4.0, 1.0, 4.0};
  m.overlap = o;
  CoverSettings con;
  con.registration_threshold = 0.1;
  const CoverResult c = greedy_cover(m, ones(6), con);
  EXPECT_EQ(c.views, (std::vector<std::uint32_t>{0, 1}));
  EXPECT_DOUBLE_EQ(c.cumulative_fraction.back(), 1.0);
  EXPECT_EQ(c.registration_components, 1u);
  ASSERT_EQ(c.registration_edges.size(), 1u);
  EXPECT_NEAR(c.registration_edges[0].sigma, 0.2, 1e-12);
  EXPECT_NEAR(registration_sigma(m, ones(6), con, 0, 1, 0.0), 0.2, 1e-12);
  EXPECT_EQ(describe_cover(m, ones(6), con, {1, 0}).registration_components, 1u);
  EXPECT_EQ(registration_component_count(m, ones(6), con, {0, 1}), 1u);
  // Above t_r = 0.2 the edge no longer suffices (the check is on the overlap's weights, not the samples').
  con.registration_threshold = 0.25;
  EXPECT_EQ(greedy_cover(m, ones(6), con).views.size(), 1u);

  // A malformed overlap is refused, by greedy and by exact cover (which counts overlap in it too:
  // ExactCover.OverlapCountedInOtherRowsConnectsTheCover).
  auto bad = std::make_shared<OverlapRows>(*o);
  bad->weight.pop_back();
  m.overlap = bad;
  EXPECT_THROW(greedy_cover(m, ones(6), con), std::invalid_argument);
  CoverSettings exact = con;
  exact.mode = CoverMode::exact;
  EXPECT_THROW(exact_cover(m, ones(6), exact), std::invalid_argument);
}

}  // namespace
}  // namespace scancell::planner
