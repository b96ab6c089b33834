// Configuration files: the shipped ones load with the thesis' values; bad ones are refused with the key path.
#include <filesystem>
#include <fstream>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/errors.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

TEST(Config, ShippedSensorIsTheThesisSensor) {
  const SensorModel s = testing::thesis_sensor();
  EXPECT_EQ(s.kind, SensorKind::line_scan);
  EXPECT_NEAR(s.fov_x_rad, 27.0 * std::numbers::pi / 180.0, 1e-12);
  EXPECT_EQ(s.baseline_mm, 180.0);
  EXPECT_EQ(s.range_min_mm, 142.0);
  EXPECT_EQ(s.range_max_mm, 407.0);
  EXPECT_EQ(s.scan_length_max_mm, 300.0);
  EXPECT_EQ(s.samples_x, 256);
  EXPECT_EQ(s.samples_y, 256);
  EXPECT_NEAR(s.grazing_yz_rad, std::numbers::pi / 3, 1e-12);
  EXPECT_NEAR(s.grazing_xz_rad, 70.0 * std::numbers::pi / 180.0, 1e-12);
  const ModelSpec spec = testing::thesis_spec();
  EXPECT_EQ(spec.precision_mm, 0.050);
  EXPECT_EQ(spec.density_per_mm2, 2.0);
  const PlannerSettings p = load_planner_settings(testing::source_path("config/planner/default.yaml"));
  EXPECT_EQ(p.viewpoints.twist_levels, 8);
  EXPECT_EQ(p.viewpoints.position_decimation, 4);
  EXPECT_EQ(p.viewpoints.min_position_spacing_fraction, 0.07);
  EXPECT_EQ(p.cover.mode, CoverMode::constrained);
}

class BadConfig : public ::testing::Test {
 protected:
  void SetUp() override {
    std::ifstream in(testing::source_path("config/sensors/line-scan-thesis.yaml"));
    good_ = std::string(std::istreambuf_iterator<char>(in), {});
    path_ = fs::temp_directory_path() / ("scancell-cfg-" + std::to_string(::getpid()) + ".yaml");
  }
  void TearDown() override { fs::remove(path_); }
  /// Loads the shipped sensor with the first `find` replaced (a whole line when `whole_line`) and returns the
  /// error message.
  std::string error_with(const std::string& find, const std::string& replacement, bool whole_line = false) {
    std::string text = good_;
    std::size_t at = text.find(find);
    EXPECT_NE(at, std::string::npos) << "not in the shipped file: " << find;
    if (at == std::string::npos) return "<pattern missing>";
    std::size_t len = find.size();
    if (whole_line) {
      at = text.rfind('\n', at) + 1;
      len = text.find('\n', at) + 1 - at;
    }
    text.replace(at, len, replacement);
    std::ofstream(path_) << text;
    try {
      load_sensor(path_);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "<accepted>";
  }
  std::string good_;
  fs::path path_;
};

TEST_F(BadConfig, MissingKeyNamesItsPath) {
  EXPECT_THAT(error_with("range_min_mm: 142", "", true), HasSubstr("range_min_mm: missing"));
  EXPECT_THAT(error_with("cz_per_mm:", "", true), HasSubstr("noise.cz_per_mm: missing"));
}

TEST_F(BadConfig, RangeMinNotBelowRangeMax) {
  EXPECT_THAT(error_with("range_min_mm: 142", "range_min_mm: 500"), HasSubstr("range_max_mm: must be greater than range_min_mm"));
}

TEST_F(BadConfig, NegativeAndNonNumericValues) {
  EXPECT_THAT(error_with("baseline_mm: 180", "baseline_mm: -180"), HasSubstr("baseline_mm: must be > 0"));
  EXPECT_THAT(error_with("baseline_mm: 180", "baseline_mm: wide"), HasSubstr("baseline_mm: cannot read 'wide' as a number"));
  EXPECT_THAT(error_with("t_yz_rad:", "  t_yz_rad: .nan\n", true), HasSubstr("grazing.t_yz_rad: must be a finite number"));
  EXPECT_THAT(error_with("samples_x: 256", "samples_x: 1"), HasSubstr("samples_x: must be >= 2"));
}

TEST_F(BadConfig, UnknownKeyIsRefused) {
  EXPECT_THAT(error_with("baseline_mm: 180", "baseline_mm: 180\nbaseline_cm: 18"), HasSubstr("baseline_cm: unknown key"));
  EXPECT_THAT(error_with("  cx: ", "  cxx: 1\n  cx: "), HasSubstr("noise.cxx: unknown key"));
}

TEST_F(BadConfig, InvalidYamlNamesTheLine) {
  EXPECT_THAT(error_with("samples_y: 256", "samples_y: [256"), HasSubstr("invalid YAML at line"));
  EXPECT_THAT(error_with("kind: line_scan", "kind: pinhole"), HasSubstr("kind: must be line_scan or random_access"));
}

// Issue 16, defect 3: deep nesting is refused by the parser with a message, before anything recurses on it.
TEST_F(BadConfig, DeepNestingIsRefusedNamingTheFile) {
  EXPECT_THAT(error_with("samples_y: 256", "samples_y: " + std::string(100000, '[') + std::string(100000, ']')),
              HasSubstr("nested deeper than a configuration ever needs"));
}

TEST(Config, MissingFileAndBadPlannerSettings) {
  EXPECT_THROW(load_sensor("/nonexistent/sensor.yaml"), ConfigError);
  const fs::path p = fs::temp_directory_path() / ("scancell-settings-" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(p) << "viewpoints:\n  twist_levels: 0\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted twist_levels 0";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("viewpoints.twist_levels: must be in [1, 360]"));
  }
  std::ofstream(p) << "viewpoints:\n  min_position_spacing_fraction: 1.5\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted min_position_spacing_fraction 1.5";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("viewpoints.min_position_spacing_fraction: must be in [0, 1], got 1.5"));
  }
  std::ofstream(p) << "cover:\n  mode: exhaustive\n";
  EXPECT_THROW(load_planner_settings(p), ConfigError);
  std::ofstream(p) << "matrix:\n  footprint_samples: 65\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted footprint_samples 65";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("matrix.footprint_samples: must be in [0, 64], got 65"));
  }
  std::ofstream(p) << "matrix:\n  footprint_samples: 8\n";
  EXPECT_EQ(load_planner_settings(p).footprint_samples, 8);
  // The key's name until session 41, when it came to apply in free space too: refused with the new name.
  std::ofstream(p) << "matrix:\n  cell_footprint_sample_area_mm2: 4\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted the old key cell_footprint_sample_area_mm2";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("matrix.cell_footprint_sample_area_mm2: was renamed matrix.footprint_sample_area_mm2"));
  }
  // A crease angle of 2 rad (115°) would take no row at all: refused, naming the key and the value.
  std::ofstream(p) << "matrix:\n  crease_angle_rad: 2\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted crease_angle_rad 2";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("matrix.crease_angle_rad: must be in [0.1, 1.5708], got 2"));
  }
  std::ofstream(p) << "matrix:\n  crease_footprint_samples: 0\n  crease_angle_rad: 0.5\n";
  EXPECT_EQ(load_planner_settings(p).crease_footprint_samples, 0);
  EXPECT_DOUBLE_EQ(load_planner_settings(p).crease_angle_rad, 0.5);
  // placement: the limits declared once (PlacementSettings) are what the loader refuses with.
  std::ofstream(p) << "placement:\n  mode: auto\n  candidates: 30\n";
  try {
    load_planner_settings(p);
    ADD_FAILURE() << "accepted placement.candidates 30";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("placement.candidates: must be in [1, 24], got 30"));
  }
  std::ofstream(p) << "placement:\n  mode: upside_down\n";
  EXPECT_THROW(load_planner_settings(p), ConfigError);
  const PlannerSettings shipped = load_planner_settings(SCANCELL_SOURCE_DIR "/config/planner/default.yaml");
  EXPECT_FALSE(shipped.placement.automatic);
  EXPECT_EQ(shipped.placement.candidates, PlacementSettings{}.candidates);
  EXPECT_DOUBLE_EQ(shipped.placement.min_tip_angle_rad, PlacementSettings{}.min_tip_angle_rad);
  fs::remove(p);
}

}  // namespace
}  // namespace scancell::planner
