#pragma once
// scancelld's configuration (config/scancelld.yaml): which cell, drivers, sensor, spec and planner settings it
// runs with (paths relative to the config file), where it keeps its data, its LCM URL, its control socket and
// the job loop's limits. Anything wrong refuses the start with "file: key.path: why" (scancell::ConfigError).
#include <chrono>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common/key_declaration.hpp"
#include "daemon/control.hpp"
#include "daemon/job_runner.hpp"
#include "drivers/config.hpp"

#include "drivers/genicam/genicam_scanner.hpp"

namespace scancell::daemon {

struct DaemonConfig {
  std::filesystem::path file;
  std::filesystem::path cell_file, drivers_file, sensor_file, spec_file, planner_file;
  std::vector<std::filesystem::path> calibration_files;  // reloaded on SIGHUP
  std::filesystem::path data_dir;
  std::string lcm_url;
  std::filesystem::path socket_path;
  ControlOptions control;  // control.group, max_clients, idle_timeout_s, send_timeout_s
  /// scanner.driver: sim (the virtual scanner in-process), sim_gige (the same, as a GigE Vision device on
  /// the loopback read through the GenICam driver), genicam (a real GenICam/GigE Vision line scanner).
  std::string scanner_driver = "sim";
  std::uint64_t scanner_seed = 1;
  drivers::GenicamConfig genicam;      // scanner.* keys of sim_gige and genicam
  std::string trigger_chip;            // genicam: the GPIO output that pulses the scanner's trigger line
  unsigned trigger_offset = 0;
  std::optional<SimTruth> truth;       // scanner.truth: what the simulated cell really is (calibration tests)
  JobSettings jobs;
  /// jobs.allowed_dirs: a client may name files (mesh, truth, spec, settings) only under these (canonical);
  /// empty: any regular file the daemon can read, said at start.
  std::vector<std::filesystem::path> allowed_dirs;
  std::chrono::milliseconds home_timeout{60000};

  std::vector<std::string> calibration_applied;  // files applied at start or reload, in order

  // Loaded from the files above.
  CellModels models;
  drivers::DriverSetup drivers;
};

/// Reads the config and every file it names. `data_dir` / `socket` override the file's values when not empty.
/// `declared`, when given, receives what the loader declares for every key of this file it reads (default
/// and range), for the test that holds docs/daemon.md's key table to it.
DaemonConfig load_daemon_config(const std::filesystem::path& file, const std::string& data_dir = "",
                                const std::string& socket = "", KeyDeclarations* declared = nullptr);

/// The calibration in force: `calibration` files of the config, then the newest result of each kind in
/// DATA_DIR/calibration/ (the daemon's own runs), applied in that order to the sensor and cell models.
void apply_calibrations(DaemonConfig& config, planner::SensorModel& sensor, planner::CellModel& cell);

/// Re-reads the calibration-bearing files (sensor model, cell model with its pose-error model) for SIGHUP;
/// returns what changed, one line per change; throws ConfigError and leaves `config` untouched when a file
/// is bad.
std::vector<std::string> reload_calibration(DaemonConfig& config);

}  // namespace scancell::daemon
