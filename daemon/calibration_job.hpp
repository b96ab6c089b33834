#pragma once
// A calibration run as a daemon job (`scancellctl calibrate KIND`): the run (calibration/runs.hpp) scans its
// target through the same acquisition code as the scan jobs, then the result is written as a versioned YAML
// file under DATA_DIR/calibration/ and applied to the models the next jobs plan with. A run that fails on bad
// data ends `failed` with the reason and changes nothing: the previous calibration stays in force.
#include <atomic>
#include <filesystem>
#include <string>

#include "daemon/job_runner.hpp"

namespace scancell::daemon {

/// "sensor", "turntable_axis" or "positioner"; anything else is refused (std::invalid_argument).
void check_calibration_kind(const std::string& kind);

/// Runs calibration job `job` of `kind`. On success the new values are in `models` (and in the file named in
/// the job's result); returns the job's state (done, failed, faulted, paused, aborted, or unchanged when
/// the daemon stops). A stopped or faulted calibration starts again from its first scan when resumed.
JobState run_calibration_job(Journal& journal, std::int64_t job, const std::string& kind, CellModels& models,
                             drivers::Positioner& positioner, const ScanHeadFactory& heads, const JobSettings& settings,
                             const std::filesystem::path& calibration_dir, const std::atomic<int>& stop,
                             const JobRunner::Report& report);

}  // namespace scancell::daemon
