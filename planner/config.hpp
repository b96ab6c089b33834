#pragma once
// YAML configuration of the sensor, the model specification and the planner settings. Every key carries its
// unit in its name; a missing, unknown, malformed or out-of-range key is refused with "file: key.path: why".
#include <cstdint>
#include <filesystem>
#include <string>

#include "planner/core/cover.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

struct PlannerSettings {
  ViewpointSettings viewpoints;
  CoverSettings cover;
  MatrixSettings matrix;
  /// matrix.countermeasures: auto — size them from the cell's pose-error model (tables 7.3-7.5); needs a cell.
  bool countermeasures_from_cell = false;
  std::uint64_t seed = 1;
  /// Keep every evaluated candidate in the plan (ViewPlan::candidate_views), for benchmarks and diagnostics.
  bool keep_candidates = false;
};

SensorModel load_sensor(const std::filesystem::path& file);
ModelSpec load_spec(const std::filesystem::path& file);
PlannerSettings load_planner_settings(const std::filesystem::path& file);

/// The same from YAML or JSON text (a plan file's `sensor` / `spec` objects); `where` prefixes messages.
SensorModel parse_sensor(const std::string& text, const std::string& where);
ModelSpec parse_spec(const std::string& text, const std::string& where);

/// The same checks load_* apply, for models built in code; throws ConfigError naming the key.
void validate(const SensorModel& sensor, const std::string& where = "sensor");
void validate(const ModelSpec& spec, const std::string& where = "spec");

const char* to_string(SensorKind k);
const char* to_string(ViewpointScheme s);
const char* to_string(CoverMode m);
const char* to_string(RegistrationNormalizer n);

}  // namespace scancell::planner
