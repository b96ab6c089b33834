#pragma once
// Calibration result files: versioned YAML with the run's kind, date, cell, a summary of its inputs, the values
// with their 95 % confidence half-widths, and residuals. The daemon loads them at start and on reload and
// hands the values to the planner and verifier (sensor noise and grazing thresholds, the turntable axis, the
// positioner's pose-error sigmas); `scancell plan|verify --calibration FILE` does the same offline.
//
//   scancell_calibration: 1
//   kind: sensor | turntable_axis | positioner
//   date: 2026-11-22T03:40:12Z
//   cell: turntable-lift-tilt
//   inputs: {scans: 21, ...}
//   values:
//     noise_cz_per_mm: {value: 5.5e-07, ci95: 2.1e-09}
//     ...
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calibration/runs.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::calibration {

struct CalibrationRecord {
  std::string kind;        // sensor | turntable_axis | positioner
  std::string date;        // UTC, ISO 8601
  std::string cell;
  nlohmann::json inputs = nlohmann::json::object();
  nlohmann::json values = nlohmann::json::object();     // name -> {value, ci95} (vectors for the axis)
  nlohmann::json residuals = nlohmann::json::object();
};

CalibrationRecord record_of(const SensorResult& r, const std::string& cell);
CalibrationRecord record_of(const AxisResult& r, const std::string& cell);
CalibrationRecord record_of(const PositionerResult& r, const std::string& cell);

/// Written to a temp file, fsynced and renamed: a reader never sees half a file.
void write_calibration(const std::filesystem::path& file, const CalibrationRecord& record);
/// Reads and checks one file; scancell::ConfigError naming the file and key for anything wrong.
CalibrationRecord load_calibration(const std::filesystem::path& file);
/// Puts the record's values into the models; returns one line per changed value ("name: old -> new").
/// A record for another cell is refused (ConfigError).
std::vector<std::string> apply_calibration(const CalibrationRecord& record, planner::SensorModel& sensor,
                                           planner::CellModel& cell);

/// The newest file of each kind in `dir` (names sort by date: KIND-YYYYMMDDTHHMMSSZ.yaml).
std::vector<std::filesystem::path> latest_calibrations(const std::filesystem::path& dir);
std::string utc_now_iso();

}  // namespace scancell::calibration
