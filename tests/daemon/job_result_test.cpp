// The closed loop's verdicts (issue 15), on round accounts written by hand: what each round predicted and
// realized, when a replan fell short, and which rows the loop gives up on.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "daemon/job_result.hpp"

namespace dm = scancell::daemon;
using nlohmann::json;

namespace {

/// One executed round's plan info: the share measured when it began, its predicted gain, the rows it
/// predicted measurable.
json round(int k, double measured_before, double predicted_mm2, std::vector<std::uint32_t> rows) {
  return {{"round", k}, {"views", 3}, {"measured_before", measured_before}, {"predicted_gain_mm2", predicted_mm2}, {"predicted_rows", rows}};
}

}  // namespace

TEST(RoundGains, RealizedIsTheCoverageRiseTimesTheArea) {
  // 1000 mm² in all: round 0 took the coverage from 0 to 0.6 (600 mm², predicted 700), round 1 from 0.6 to
  // 0.61 (10 mm², predicted 100: 10 %, under 20 %).
  const std::vector<json> infos{round(0, 0.0, 700.0, {0, 1}), round(1, 0.6, 100.0, {2, 3})};
  const json g = dm::round_gains(infos, 0.61, 1000.0);
  ASSERT_EQ(g.size(), 2u);
  EXPECT_NEAR(g[0]["realized_gain_mm2"].get<double>(), 600.0, 1e-9);
  EXPECT_NEAR(g[0]["realized_share"].get<double>(), 600.0 / 700.0, 1e-12);
  EXPECT_FALSE(g[0]["under_20_percent"].get<bool>());
  EXPECT_NEAR(g[1]["realized_gain_mm2"].get<double>(), 10.0, 1e-9);
  EXPECT_TRUE(g[1]["under_20_percent"].get<bool>());
}

TEST(ReplanFellShort, OnlyAReplanThatMeasuredNothingOrUnderAFifth) {
  const double total = 1000.0;
  // A setup's first round is never judged so: it is the single shot, not a replan.
  EXPECT_FALSE(dm::replan_fell_short({round(0, 0.0, 700.0, {0})}, 0.01, total));
  const json first = round(0, 0.0, 700.0, {0});
  // A replan that predicted 100 mm²: 19 mm² falls short, 21 mm² does not, nothing new does.
  EXPECT_TRUE(dm::replan_fell_short({first, round(1, 0.6, 100.0, {1})}, 0.619, total));
  EXPECT_FALSE(dm::replan_fell_short({first, round(1, 0.6, 100.0, {1})}, 0.621, total));
  EXPECT_TRUE(dm::replan_fell_short({first, round(1, 0.6, 0.0, {1})}, 0.6, total));
}

TEST(GivenUpRows, RowsOfAWeakReplanAndRowsThatFailedTooOften) {
  const double total = 1000.0;
  // Rows 0-5; round 0 predicted 0, 1, 2; round 1 (a replan) predicted 2, 3, 4. Measured now: 0 and 3.
  const std::vector<std::uint8_t> measured{1, 0, 0, 1, 0, 0};
  const std::vector<json> infos{round(0, 0.0, 700.0, {0, 1, 2}), round(1, 0.6, 100.0, {2, 3, 4})};
  // Row 2 failed twice, rows 1 and 4 once; row 5 was never predicted.
  const auto fails = dm::failure_counts(infos, measured);
  EXPECT_EQ(fails, (std::vector<std::uint8_t>{0, 1, 2, 0, 1, 0}));
  // The replan realized 50 of 100 mm²: only the twice-failed row is given up (retire after 2).
  EXPECT_EQ(dm::given_up_rows(infos, measured, 0.65, 2, total), (std::vector<std::uint8_t>{0, 0, 1, 0, 0, 0}));
  // It realized 10 of 100 mm²: every unmeasured row it predicted (2 and 4) is given up, row 1 is not.
  EXPECT_EQ(dm::given_up_rows(infos, measured, 0.61, 2, total), (std::vector<std::uint8_t>{0, 0, 1, 0, 1, 0}));
}
