// Calibration: the fits on synthetic data with known answers, the targets' geometry, and each run as a daemon
// job on the simulated cell (in-process Modbus drives, the simulated scan head) whose truth differs from the
// daemon's models: the runs must recover the truth to the tolerances, and bad data must leave the
// previous calibration in force.
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "calibration/fit.hpp"
#include "calibration/results.hpp"
#include "calibration/targets.hpp"
#include "daemon/calibration_job.hpp"
#include "daemon/cell_io.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"

namespace scancell::calibration {
namespace {

namespace fs = std::filesystem;
namespace sp = scancell::planner;
namespace dm = scancell::daemon;
namespace dr = scancell::drivers;
using namespace std::chrono_literals;
using ::testing::HasSubstr;

constexpr double kDeg = std::numbers::pi / 180.0;
std::string src(const std::string& rel) { return std::string(SCANCELL_SOURCE_DIR) + "/" + rel; }

double signed_volume(const sp::TriangleMesh& m) {
  double v = 0.0;
  for (const auto& t : m.triangles) v += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6.0;
  return v;
}

TEST(Fit, SphereCircleAndPlaneRecoverKnownGeometry) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // A cap (polar angle < 60°) of a sphere r = 12.5 at (10, -4, 30), 0.01 mm noise.
  const Eigen::Vector3d c(10, -4, 30);
  std::vector<Eigen::Vector3d> cap;
  for (int i = 0; i < 3000; ++i) {
    const double th = std::acos(1.0 - u(rng) * (1.0 - std::cos(60 * kDeg))), ph = 2 * std::numbers::pi * u(rng);
    cap.push_back(c + (12.5 + noise(rng)) * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)));
  }
  const SphereFit free = fit_sphere(cap, "cap");
  EXPECT_LT((free.centre - c).norm(), 0.01);
  EXPECT_NEAR(free.radius, 12.5, 0.01);
  EXPECT_NEAR(free.rms, 0.01, 0.001);
  EXPECT_LT((fit_sphere(cap, "cap", 12.5).centre - c).norm(), 0.005);
  // Eight points on a circle about a tilted axis.
  const Eigen::Vector3d axis = Eigen::Vector3d(0.01, -0.02, 1).normalized(), centre(1, 2, 3);
  const Eigen::Vector3d e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
  std::vector<Eigen::Vector3d> ring;
  for (int k = 0; k < 8; ++k) ring.push_back(centre + 55.0 * (std::cos(k * 0.785) * e1 + std::sin(k * 0.785) * e2));
  const CircleFit cf = fit_circle(ring, "ring");
  EXPECT_LT(std::acos(std::abs(cf.normal.dot(axis))), 1e-9);
  EXPECT_LT((cf.centre - centre).norm(), 1e-9);
  EXPECT_NEAR(cf.radius, 55.0, 1e-9);
  // y = 3 x exactly, then with scatter: k and its standard error.
  const ProportionalFit pf = fit_proportional({1, 2, 3, 4}, {3.1, 5.9, 9.0, 12.1}, "line");
  EXPECT_NEAR(pf.k, 3.0, 0.02);
  EXPECT_GT(pf.se, 0.0);
  // Too little data is refused by name.
  try {
    fit_sphere({c, c, c}, "sphere scan 3");
    FAIL() << "no error";
  } catch (const scancell::DataError& e) {
    EXPECT_THAT(e.what(), HasSubstr("sphere scan 3"));
  }
  EXPECT_THROW(fit_plane(std::vector<Eigen::Vector3d>(20, c), "line"), scancell::DataError);
  EXPECT_THROW(fit_circle({c, c, c}, "ring"), scancell::DataError);
}

TEST(Targets, ClosedWithOutwardNormalsAndTheRampFaceWhereItSays) {
  const Ramp ramp;
  EXPECT_NEAR(signed_volume(plate_target()), kPlateSideMm * kPlateSideMm * kPlateThicknessMm, 1e-6);
  const double wedge = 2 * ramp.half_width_mm * 0.5 * (2 * ramp.half_depth_mm) * (2 * ramp.half_depth_mm * std::tan(ramp.slope_rad));
  EXPECT_NEAR(signed_volume(ramp_target(ramp)), wedge, 1e-6 * wedge);
  const double ball = 4.0 / 3.0 * std::numbers::pi * std::pow(12.5, 3);
  EXPECT_NEAR(signed_volume(spheres_target(tripod())), 3 * ball, 1e-3 * 3 * ball);
  const sp::TriangleMesh r = ramp_target(ramp);
  const auto& t = r.triangles[0];  // the sloped face
  const Eigen::Vector3d n = (r.vertices[t[1]] - r.vertices[t[0]]).cross(r.vertices[t[2]] - r.vertices[t[0]]).normalized();
  EXPECT_LT((n - ramp.normal()).norm(), 1e-12);
  EXPECT_TRUE(on_ramp_face(ramp, ramp.centre(), 3.0, 0.1));
  EXPECT_FALSE(on_ramp_face(ramp, ramp.centre() + Eigen::Vector3d(0, 0, 5), 3.0, 1.0));
}

/// The simulated cell whose truth differs from the daemon's models.
struct CalibrationCell : ::testing::Test {
  fs::path dir;
  dm::CellModels models;
  std::unique_ptr<dm::CellIo> io;
  std::unique_ptr<dm::Journal> journal;
  dm::SimTruth truth;
  bool empty_table = false;  // bad data: the target is missing

  void SetUp() override {
    dir = fs::temp_directory_path() / ("scancell_cal_" + std::to_string(::getpid()) + "_" +
                                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    models.cell = sp::load_cell(src("config/cells/turntable-lift-tilt.yaml"));
    // Thirty times the real cell's speeds: the same motion, sooner (the runs measure geometry, not time).
    for (auto& a : models.cell.axes) {
      a.max_speed *= 30.0;
      a.max_accel *= 100.0;
    }
    models.sensor = sp::load_sensor(src("config/sensors/line-scan-thesis.yaml"));
    models.spec = sp::load_spec(src("config/spec/thesis.yaml"));
    dr::DriverSetup setup;
    for (const auto& a : models.cell.axes) setup.axes[a.name] = dr::SimAxisConfig{};
    io = dm::open_cell_io(models.cell, setup, "test drivers");
    dm::bring_up(*io, models.cell, 10000ms);
    journal = std::make_unique<dm::Journal>(dir / "data");
    truth.seed = 11;
  }
  void TearDown() override { fs::remove_all(dir); }

  dm::JobState run(const std::string& kind, std::int64_t* job_out = nullptr) {
    const std::int64_t job = journal->create_job("calibration:" + kind, nlohmann::json({{"calibrate", kind}}).dump());
    if (job_out) *job_out = job;
    dm::JobSettings settings;
    settings.scan_speed_mm_s = 1000.0;
    std::atomic<int> stop{0};
    auto heads = [&](const sp::TriangleMesh& scene, std::size_t object_triangles, const sp::CellModel& placed) {
      // Bad data: nothing on the table but the table itself, which the scanner sees like any surface.
      if (empty_table) return dm::make_sim_head(models.sensor, sp::fixture_mesh(placed), 0, 3, &placed, &truth);
      return dm::make_sim_head(models.sensor, scene, object_triangles, 3, &placed, &truth);
    };
    return dm::run_calibration_job(*journal, job, kind, models, io->positioner, heads, settings, dir / "calibration", stop,
                                   [](const dm::Progress&) {});
  }
};

TEST_F(CalibrationCell, SensorRunRecoversNoiseAndGrazingThresholds) {
  sp::SensorModel t = models.sensor;
  t.noise_cz_per_mm *= 1.12;     // the real sensor is noisier than its data sheet
  t.grazing_xz_rad = 66 * kDeg;  // and gives up earlier
  t.grazing_yz_rad = 57 * kDeg;
  t.noise_cx = 1.5e-4;           // lateral noise unlike the data sheet's 1e-4
  t.noise_cy = 0.6e-4;
  truth.sensor = t;
  std::int64_t job = 0;
  ASSERT_EQ(run("sensor", &job), dm::JobState::done) << journal->job(job).cause;
  std::cout << "C_z " << models.sensor.noise_cz_per_mm << " (truth " << t.noise_cz_per_mm << "), t_xz "
            << models.sensor.grazing_xz_rad / kDeg << "° (66°), t_yz " << models.sensor.grazing_yz_rad / kDeg << "° (57°)\n";
  std::cout << "C_x " << models.sensor.noise_cx << " (1.5e-4), C_y " << models.sensor.noise_cy << " (0.6e-4)\n";
  EXPECT_NEAR(models.sensor.noise_cz_per_mm / t.noise_cz_per_mm, 1.0, 0.05);
  EXPECT_NEAR(models.sensor.noise_cx / t.noise_cx, 1.0, 0.1);
  EXPECT_NEAR(models.sensor.noise_cy / t.noise_cy, 1.0, 0.1);
  EXPECT_NEAR(models.sensor.grazing_yz_rad, t.grazing_yz_rad, 2 * kDeg);
  EXPECT_NEAR(models.sensor.grazing_xz_rad, t.grazing_xz_rad, 2 * kDeg);
  // The result file is versioned, names its cell, and loads back to the same values.
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  const CalibrationRecord rec = load_calibration(result["file"].get<std::string>());
  EXPECT_EQ(rec.kind, "sensor");
  EXPECT_EQ(rec.cell, "turntable-lift-tilt");
  EXPECT_NEAR(rec.values["noise_cz_per_mm"]["value"].get<double>(), models.sensor.noise_cz_per_mm, 1e-15);
  EXPECT_GT(rec.values["noise_cz_per_mm"]["ci95"].get<double>(), 0.0);
}

TEST_F(CalibrationCell, TurntableAxisRunRecoversATiltedOffsetAxis) {
  truth.table_axis_point_mm = Eigen::Vector3d(0.6, -0.4, 0.0);
  truth.table_axis_direction = Eigen::AngleAxisd(0.15 * kDeg, Eigen::Vector3d(1, 1, 0).normalized()) * Eigen::Vector3d::UnitZ();
  std::int64_t job = 0;
  ASSERT_EQ(run("turntable_axis", &job), dm::JobState::done) << journal->job(job).cause;
  const double angle = std::acos(std::clamp(models.cell.table_axis_direction.dot(truth.table_axis_direction), -1.0, 1.0));
  std::cout << "axis direction off by " << angle / kDeg << "°, point off by "
            << (models.cell.table_axis_point_mm - truth.table_axis_point_mm).head<2>().norm() << " mm\n";
  EXPECT_LT(angle, 0.05 * kDeg) << models.cell.table_axis_direction.transpose();
  EXPECT_LT((models.cell.table_axis_point_mm - truth.table_axis_point_mm).head<2>().norm(), 0.1)
      << models.cell.table_axis_point_mm.transpose();
  // With the calibrated axis the kinematics reach poses through it: the IK round trip holds.
  sp::JointVector q = models.cell.home();
  q[0] = 1.0;
  const Eigen::Isometry3d pose = sp::forward_kinematics(models.cell, q);
  const sp::IkResult ik = sp::inverse_kinematics(models.cell, pose, 50.0);
  ASSERT_TRUE(ik.ok) << ik.why;
  EXPECT_LT((sp::forward_kinematics(models.cell, ik.q).translation() - pose.translation()).norm(), 1e-6);
}

TEST_F(CalibrationCell, PositionerRunRecoversPoseErrorSigmas) {
  truth.pose_error = {0.2, 0.003, 0.003};
  std::int64_t job = 0;
  ASSERT_EQ(run("positioner", &job), dm::JobState::done) << journal->job(job).cause;
  std::cout << "sigma_p " << models.cell.pose_error.sigma_p_mm << " mm (0.2), sigma_a " << models.cell.pose_error.sigma_a_rad
            << " rad (0.003), sigma_t " << models.cell.pose_error.sigma_t_rad << " rad (0.003)\n";
  EXPECT_NEAR(models.cell.pose_error.sigma_p_mm / 0.2, 1.0, 0.2);
  EXPECT_NEAR(models.cell.pose_error.sigma_a_rad / 0.003, 1.0, 0.2);
  EXPECT_NEAR(models.cell.pose_error.sigma_t_rad / 0.003, 1.0, 0.25);
}

TEST_F(CalibrationCell, NoTargetOnTheTableFailsAndKeepsThePreviousCalibration) {
  empty_table = true;
  const sp::CellModel before = models.cell;
  std::int64_t job = 0;
  EXPECT_EQ(run("turntable_axis", &job), dm::JobState::failed);
  EXPECT_THAT(journal->job(job).cause, HasSubstr("sphere scan"));
  EXPECT_THAT(journal->job(job).cause, HasSubstr("previous calibration stays in force"));
  EXPECT_EQ(models.cell.table_axis_direction, before.table_axis_direction);
  EXPECT_FALSE(fs::exists(dir / "calibration") && !fs::is_empty(dir / "calibration"));
}

TEST(CalibrationFile, DamageIsRefusedNamingTheKey) {
  const fs::path d = fs::temp_directory_path() / ("scancell_calfile_" + std::to_string(::getpid()));
  fs::create_directories(d);
  auto refused = [&](const std::string& text, const std::string& expect) {
    std::ofstream(d / "c.yaml") << text;
    try {
      load_calibration(d / "c.yaml");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const scancell::ConfigError& e) {
      EXPECT_THAT(e.what(), HasSubstr(expect)) << text;
    }
  };
  const std::string head = "scancell_calibration: 1\nkind: sensor\ndate: x\ncell: c\ninputs: {}\n";
  refused("scancell_calibration: 2\nkind: sensor\ndate: x\ncell: c\ninputs: {}\nvalues: {}\n", "version 2");
  refused(head + "values: {noise_cz_per_mm: {value: 1e-7, ci95: 0}}\n", "grazing_xz_rad");
  refused(head + "values: {noise_cz_per_mm: {value: -1, ci95: 0}, grazing_xz_rad: {value: 1, ci95: 0}, grazing_yz_rad: {value: 1, ci95: 0}}\n",
          "noise_cz_per_mm");
  refused("scancell_calibration: 1\nkind: lens\ndate: x\ncell: c\ninputs: {}\nvalues: {}\n", "kind");
  // A record of another cell is not applied.
  CalibrationRecord r{"positioner", "d", "other-cell"};
  r.values = {{"sigma_p_mm", {{"value", 0.1}, {"ci95", 0.01}}}, {"sigma_a_rad", {{"value", 0.001}, {"ci95", 0.0}}}, {"sigma_t_rad", {{"value", 0.001}, {"ci95", 0.0}}}};
  sp::SensorModel s;
  sp::CellModel c;
  c.name = "turntable-lift-tilt";
  EXPECT_THROW(apply_calibration(r, s, c), scancell::ConfigError);
  fs::remove_all(d);
}

}  // namespace
}  // namespace scancell::calibration
