#pragma once
// A job's end, in figures and files: the rough model's unmeasured rows by cause, the closed loop's account
// (each round's predicted and realized gain, the rows it gave up on) and, in simulation, the checks against
// the object really on the table. Free functions of plain values: JobRunner::finish composes them.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "planner/core/rough_model.hpp"
#include "planner/core/sensor.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::daemon {

/// The rough model's unmeasured rows by what keeps a job open: open (seen surface some view of this cell
/// measures), unmeasurable (no candidate view does), guessed (hypothetical: the rough scan never saw it).
struct RowTally {
  std::size_t open = 0, guessed = 0, hypothetical = 0;  // hypothetical: guessed, with the unmeasurable ones
  double unmeasured_area = 0.0, open_area = 0.0, impossible_area = 0.0, guessed_area = 0.0, hypothetical_area = 0.0;
};

RowTally tally_unmeasured(const planner::RoughModel& rough, const std::vector<std::uint32_t>& unmeasured,
                          const std::vector<std::uint32_t>& unmeasurable);

/// The rows a round holds against itself: those a view predicted and measured no profile's worth of harm
/// to. A row a view's sweep passed without a profile (a loaded host, a scanner that dropped frames) did not
/// fail for its geometry, so that view's prediction of it is not held against it and the loop may aim at it
/// again. The round info lists `view_rows` per view (plans before it had only `predicted_rows`: all held) and,
/// added by the runner from the stored scans, `excused_rows` (view index -> rows passed without a profile).
std::vector<std::uint32_t> held_rows(const nlohmann::json& info);

/// The closed loop's evidence: per row, how many executed rounds predicted it measurable while it is still
/// unmeasured (each round's plan info keeps its predicted rows; what is measured now is the coverage).
/// Rows a round predicted through views that lost profiles only are not counted (held_rows).
std::vector<std::uint8_t> failure_counts(const std::vector<nlohmann::json>& round_infos, const std::vector<std::uint8_t>& measured);

/// Rows the closed loop gives up on (needs attention): predicted measurable by `retire_after` executed rounds
/// and still unmeasured, or predicted by a replanning round that measured nothing new at all or realized
/// under 20 % of its predicted gain — that round's predictions did not hold, and the loop stops there, so
/// its rows are not chased again either. `total_mm2`: the rough model's area.
std::vector<std::uint8_t> given_up_rows(const std::vector<nlohmann::json>& round_infos, const std::vector<std::uint8_t>& measured,
                                        double measured_now, int retire_after, double total_mm2);

/// Issue 15, the loop's one verdict on its last round: true when `round_infos` (one setup's executed rounds)
/// ends in a replanning round (not the setup's first) that measured nothing new or realized under 20 % of
/// its predicted gain. The loop stops after such a round, and `given_up_rows` gives up on its rows.
bool replan_fell_short(const std::vector<nlohmann::json>& round_infos, double measured_now, double total_mm2);

/// Each executed round's predicted and realized gain (mm²): realized is what the measured coverage rose by
/// from the round's start to the next round's start (or to `measured_now` for the last).
nlohmann::json round_gains(const std::vector<nlohmann::json>& round_infos, double measured_now, double total_mm2);

/// `dir`/unmeasured.xyz: the rows not measured to the spec as points for a viewer (object frame: x y z, the
/// normal, the row's area). Returns the file's path.
std::filesystem::path write_unmeasured_rows(const planner::RoughModel& rough, const std::vector<std::uint32_t>& rows,
                                            const std::filesystem::path& dir);

/// The closed loop's account at the job's end: `round_gains`, `rounds_under_20_percent` (realized under 20 %
/// of the predicted gain), and the rows it gave up on (`needs_attention_rows`, `_area_mm2`, and the points in
/// `dir`/needs_attention.xyz with the rounds each failed). `measured`: 1 for rows measured or unmeasurable.
nlohmann::json closed_loop_account(const planner::RoughModel& rough, const std::vector<nlohmann::json>& round_infos,
                                   const std::vector<std::uint8_t>& measured, double measured_now, int retire_after,
                                   const std::filesystem::path& dir);

/// Simulation only (the scans carry the simulator's ground truth): the rough model's coverage counted from
/// where the samples really are, and only samples within 3 × the precision spec of the true surface along
/// its normal (`verified_coverage`); the samples' error from the true hit points (`sample_error_rms_mm`,
/// `sample_normal_error_rms_mm`, `samples_off_spec`); verified measurability m_v of the scans on `truth`
/// (`verified_mv`, `verified_against`) with its picture and coloured mesh in `dir` (`coverage_png`, `coverage_ply`).
nlohmann::json simulation_truth_checks(const std::vector<planner::RangeImage>& images, const planner::RoughModel* rough,
                                       const planner::ModelSpec& spec, const planner::CoverageOptions& coverage,
                                       const planner::TriangleMesh& truth, const std::string& truth_name,
                                       const std::filesystem::path& dir);

}  // namespace scancell::daemon
