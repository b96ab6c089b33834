// The job runner on a simulated cell: in-process Modbus drives (real libmodbus over loopback TCP, the same
// ModbusAxis code as a real drive), the simulated scan head, a real SQLite journal.
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/test_png.hpp"
#include "daemon/acquire.hpp"
#include "daemon/cell_io.hpp"
#include "daemon/job_runner.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/reconstruction/rough_scan.hpp"
#include "planner/sim/synthetic.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::daemon {
namespace {

namespace fs = std::filesystem;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace std::chrono_literals;
using ::testing::HasSubstr;

std::string src(const std::string& rel) { return std::string(SCANCELL_SOURCE_DIR) + "/" + rel; }

/// A closed box of `size` mm (corner at the origin), edges split to 6 mm, written as OFF.
std::string write_box(const fs::path& dir, const Eigen::Vector3d& s, const std::string& name) {
  sp::TriangleMesh box;
  box.vertices = {{0, 0, 0}, {s.x(), 0, 0}, {s.x(), s.y(), 0}, {0, s.y(), 0},
                  {0, 0, s.z()}, {s.x(), 0, s.z()}, {s.x(), s.y(), s.z()}, {0, s.y(), s.z()}};
  box.triangles = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                   {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
  const sp::TriangleMesh m = sp::refine_edges(box, 6.0);
  const fs::path path = dir / name;
  std::ofstream f(path);
  f << "OFF\n" << m.vertices.size() << ' ' << m.triangles.size() << " 0\n";
  for (const auto& v : m.vertices) f << v.x() << ' ' << v.y() << ' ' << v.z() << "\n";
  for (const auto& t : m.triangles) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
  return path.string();
}

/// A closed 50 mm cube: its base sits on the turntable plate, so the planner knows the base (1/6 of the
/// area) cannot be measured in this cell.
std::string write_cube(const fs::path& dir) { return write_box(dir, Eigen::Vector3d(50, 50, 50), "cube.off"); }

struct SimCell : ::testing::Test {
  fs::path dir;
  CellModels models;
  std::unique_ptr<CellIo> io;
  std::unique_ptr<Journal> journal;
  std::vector<Progress> reports;
  std::mutex mu;

  void SetUp() override {
    dir = fs::temp_directory_path() / ("scancell_job_" + std::to_string(::getpid()) + "_" +
                                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
    models.cell = sp::load_cell(src("config/cells/turntable-lift-tilt.yaml"));
    // Ten times the real cell's speeds: the same motion, sooner.
    for (auto& a : models.cell.axes) {
      a.max_speed *= 10.0;
      a.max_accel *= 20.0;
    }
    models.sensor = sp::load_sensor(src("config/sensors/line-scan-thesis.yaml"));
    models.spec = sp::load_spec(src("config/spec/thesis.yaml"));
    models.settings = sp::load_planner_settings(src("config/planner/default.yaml"));
    dr::DriverSetup setup;
    for (const auto& a : models.cell.axes) setup.axes[a.name] = dr::SimAxisConfig{};
    io = open_cell_io(models.cell, setup, "test drivers");
    bring_up(*io, models.cell, 10000ms);
    journal = std::make_unique<Journal>(dir / "data");
  }
  void TearDown() override {
    if (const char* keep = std::getenv("SCANCELL_KEEP_TEST_DIR"); keep && *keep) std::cout << "kept " << dir << "\n";
    else fs::remove_all(dir);
  }

  std::optional<SimTruth> truth;
  bool register_views = true;
  int max_rounds = 4;
  double scan_speed = 400.0;
  bool drive_compare = false;  // scanner.trigger_source: drive_compare instead of the daemon's polled compare
  // Planning the next setup costs four plans at a job's end (a minute under ASan across these tests): only
  // the test that checks it asks for it.
  double next_setup_min_area_mm2 = 0.0;
  int max_setups = 1;
  double sim_placement_error_mm = 0.0, sim_placement_error_rad = 0.0;
  std::function<void(const Progress&)> on_report;

  JobRunner runner() {
    JobSettings s;
    s.max_setups = max_setups;
    s.sim_placement_error_mm = sim_placement_error_mm;
    s.sim_placement_error_rad = sim_placement_error_rad;
    s.scan_speed_mm_s = scan_speed;
    s.drive_compare = drive_compare;
    s.register_views = register_views;
    s.max_rounds = max_rounds;
    s.next_setup_min_area_mm2 = next_setup_min_area_mm2;
    s.jobs_dir = dir / "data" / "jobs";
    auto heads = [this](const sp::TriangleMesh& scene, std::size_t object_triangles, const sp::CellModel& placed) {
      return make_sim_head(models.sensor, scene, object_triangles, 7, &placed, truth ? &*truth : nullptr);
    };
    return JobRunner(*journal, models, io->positioner, heads, s, [this](const Progress& p) {
      std::lock_guard<std::mutex> lock(mu);
      reports.push_back(p);
      if (on_report) on_report(p);
    });
  }
  std::int64_t submit(const std::string& mesh, double fit_mm = 0.0) {
    JobRequest r;
    r.mesh = mesh;
    r.fit_mm = fit_mm;
    r.rough_vertices = 600;
    validate_request(r);
    return journal->create_job(mesh, r.to_json().dump());
  }
  std::size_t stored_views(std::int64_t job) {
    std::size_t n = 0;
    for (auto p : journal->plans(job)) n += journal->scans(p).size();
    return n;
  }
};

// A calibration sweep with a run of lost profiles is taken again (the CI flake: a loaded machine lost the
// profiles across one sphere of the tripod and the positioner run failed with "0 points"); single lost
// profiles are not a hole, and when every take has one the shortest gap wins.
TEST(TakeWhole, RetakesASweepWithARunOfLostProfilesAndKeepsTheBestTake) {
  std::vector<std::vector<int>> lost;  // per take: the rows lost
  std::size_t calls = 0;
  std::vector<std::string> log;
  const auto take = [&] {
    Acquisition a;
    a.image.rows = 200;
    a.image.acquired_rows.assign(200, 1);
    for (const int r : lost.at(calls)) a.image.acquired_rows[static_cast<std::size_t>(r)] = 0;
    a.lost_profiles = static_cast<int>(lost.at(calls).size());
    ++calls;
    return a;
  };
  const auto run = [](int from, int n) {
    std::vector<int> v;
    for (int r = from; r < from + n; ++r) v.push_back(r);
    return v;
  };
  lost = {run(50, 40), {3, 9, 100, 150}};  // a 40-row hole, then four scattered single losses
  EXPECT_EQ(longest_lost_run(take().image), 40);
  calls = 0;
  const Acquisition got = take_whole(take, 3, 4, [&](const std::string& l) { log.push_back(l); });
  EXPECT_EQ(got.lost_profiles, 4);
  EXPECT_EQ(calls, 2u);
  ASSERT_EQ(log.size(), 1u);
  EXPECT_EQ(log[0], "40 profiles in a row lost in the sweep (40 of 200 in all); taking it again (attempt 2 of 3)");
  calls = 0;
  lost = {run(10, 30), run(10, 9), run(0, 12)};
  EXPECT_EQ(longest_lost_run(take_whole(take, 3, 4).image), 9);  // every take has a hole: the shortest
  EXPECT_EQ(calls, 3u);
  calls = 0;
  lost = {{7, 8, 9}};
  EXPECT_EQ(take_whole(take, 3, 4).lost_profiles, 3);  // a gap within the limit is taken once
  EXPECT_EQ(calls, 1u);
  EXPECT_THROW(take_whole(take, 0, 4), scancell::DataError);
}

// Issue 15: a row the sweep passed without a profile did not fail for its geometry. A 10-row sweep, profile
// j in the view-frame plane y = 2 j - 9 mm, the view turned 90° about x (object z = view y), row 5 lost:
// points between rows 3 and 7 lie in or beside the lost profile, the others not.
TEST(LostProfiles, RowsInOrBesideALostProfileArePassedTheRestAreNot) {
  sp::RangeImage img;
  img.rows = 10;
  img.columns = 3;
  img.pose.camera_to_object = Eigen::Translation3d(5.0, 0.0, 0.0) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX());
  img.samples.assign(30, sp::RangeSample{});
  img.acquired_rows.assign(10, 1);
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 3; ++i) {
      auto& s = img.samples[static_cast<std::size_t>(j * 3 + i)];
      s.camera_mm = Eigen::Vector3f(float(i), float(2 * j - 9), -100.0f);
      s.measured = j != 5;
    }
  img.acquired_rows[5] = 0;
  // A view-frame y maps to object z = y (rotation by 90° about x), offset 5 mm in x.
  const auto at_row = [](double j) { return Eigen::Vector3d(5.0, 100.0, 2.0 * j - 9.0); };
  const std::vector<Eigen::Vector3d> points = {at_row(1), at_row(3.9), at_row(4.2), at_row(5), at_row(6.5), at_row(7.2), at_row(30)};
  const std::vector<std::uint32_t> all = {0, 1, 2, 3, 4, 5, 6};
  EXPECT_EQ(rows_passed_without_profile(img, points, all), (std::vector<std::uint32_t>{1, 2, 3, 4}));
  img.acquired_rows[5] = 1;  // every profile came: nothing is passed
  EXPECT_TRUE(rows_passed_without_profile(img, points, all).empty());
  img.acquired_rows.assign(10, 0);  // one profile came: the rows' planes are unknown, every row was passed
  img.acquired_rows[0] = 1;
  for (std::size_t k = 3; k < img.samples.size(); ++k) img.samples[k].measured = false;
  EXPECT_EQ(rows_passed_without_profile(img, points, all), all);
  EXPECT_THROW(rows_passed_without_profile(img, points, {7}), scancell::DataError);
}

/// A head whose scanner loses the first profile fired at each of chosen rows (a frame lost on the wire), the
/// sim head's otherwise. The row of a pulse is read from the sweep position it was fired at.
struct LossyHead : ScanHead, drivers::Scanner {
  std::unique_ptr<ScanHead> inner;
  std::set<int> lose_rows;
  double start_mm = 0.0, pitch_mm = 1.0;
  std::size_t sweep = 4;
  std::vector<int> fired_row;  // per pulse
  std::set<int> lost;
  dr::DigitalOutput& trigger() override { return inner->trigger(); }
  dr::Scanner& scanner() override { return *this; }
  void camera_at(const sp::JointVector& q, const Eigen::Isometry3d& m) override {
    fired_row.push_back(static_cast<int>(std::floor((q[sweep] - start_mm + 5e-4) / pitch_mm)));
    inner->camera_at(q, m);
  }
  void compare_pulse(const sp::JointVector& q, const Eigen::Isometry3d& m) override {
    fired_row.push_back(static_cast<int>(std::floor((q[sweep] - start_mm + 5e-4) / pitch_mm)));
    compare_at.push_back(q[sweep]);
    inner->compare_pulse(q, m);
  }
  std::vector<double> compare_at;  // per compare pulse: the sweep position it came at
  void moved() override { inner->moved(); }
  std::set<int> swallow_rows;  // the first profile fired at these never comes at all (the sweep's last frame lost)
  std::set<int> swallowed;
  dr::Profile acquire(std::chrono::milliseconds timeout) override {
    while (true) {
      dr::Profile p = inner->scanner().acquire(timeout);
      const int row = fired_row.at(p.index);
      if (swallow_rows.count(row) && swallowed.insert(row).second) continue;
      if (lose_rows.count(row) && lost.insert(row).second) {
        p.lost = true;
        p.samples.clear();
      }
      return p;
    }
  }
};

// A view's sweep whose profiles of rows 40-44 and 100 are lost, and whose last four never arrive at all (the
// sweep's last frame lost: the scanner goes quiet, acquire_view's wait times out and keeps what came): the
// sweep axis returns and sweeps again firing only at the rows left without a profile, and they land where they belong (between their neighbours in
// the view frame, on the row-index line of the first pass). With fill_sweeps 0 the holes stay and are counted.
using scancell::test_support::expect_whole_png;

TEST_F(SimCell, FillSweepsTakeTheProfilesASweepMissedAndOnlyThose) {
  sp::TriangleMesh cube = sp::load_mesh(write_cube(dir));
  for (auto& v : cube.vertices) v -= Eigen::Vector3d(25, 25, 0);
  const double L = 60.0;
  const sp::IkResult ik = sp::look_at(models.cell, Eigen::Vector3d(25, 0, 25), 160.0, 0.0, 0.0, L);
  ASSERT_TRUE(ik.ok) << ik.why;
  const auto take = [&](int fills) {
    LossyHead head;
    head.inner = make_sim_head(models.sensor, cube, cube.triangles.size(), 7, &models.cell, nullptr);
    head.lose_rows = {40, 41, 42, 43, 44, 100};
    head.swallow_rows = {252, 253, 254, 255};
    head.sweep = models.cell.axis_index("sweep");
    head.start_mm = ik.q[head.sweep] - 0.5 * L;
    head.pitch_mm = L / 255.0;
    JobSettings s;
    s.scan_speed_mm_s = scan_speed;
    s.fill_sweeps = fills;
    std::atomic<int> stop{0};
    Acquisition a = acquire_view(io->positioner, head, models.cell, models.sensor, ik.q, L, s, stop);
    return std::make_pair(a, head.pulses);
  };
  // Up to five fill sweeps, the most jobs.fill_sweeps allows: each halves the speed, so a host so loaded that its
  // position reads miss rows at 400 and 200 mm/s (two busy loops per core: 9 of 12 runs with two fill sweeps
  // left rows 40-44 or 252 without a profile) takes them by 12.5 mm/s. Only missing rows are fired again.
  const auto [got, pulses] = take(5);
  const sp::RangeImage& img = got.image;
  ASSERT_GE(got.fill_sweeps, 1);
  EXPECT_GE(got.filled_profiles, 10);
  // Only the missing rows are fired again: a pass over every row would fire 256 more.
  EXPECT_LT(pulses, 256u + 64u);
  EXPECT_EQ(got.lost_profiles, 256 - static_cast<int>(std::count(img.acquired_rows.begin(), img.acquired_rows.end(), 1)));
  const auto mean_y = [&](int j) {
    double y = 0;
    int k = 0;
    for (int i = 0; i < img.columns; ++i)
      if (img.at(i, j).valid()) {
        y += img.at(i, j).camera_mm.y();
        ++k;
      }
    return k ? y / k : std::nan("");
  };
  const double pitch = L / 255.0;
  for (const int j : {252, 253, 254, 255}) EXPECT_TRUE(img.acquired_rows[static_cast<std::size_t>(j)]) << "row " << j;
  for (const int j : {40, 41, 42, 43, 44, 100}) {  // on the cube's face (the last rows sweep past its edge)
    ASSERT_TRUE(img.acquired_rows[static_cast<std::size_t>(j)]) << "row " << j;
    // The view frame's y runs along the sweep: row j sits at -L/2 + j pitch (fired at the position read
    // back, so up to a pitch beyond it).
    const double y = mean_y(j), want = -0.5 * L + j * pitch;
    EXPECT_GT(y, want - 0.2 * pitch) << "row " << j;
    EXPECT_LT(y, want + 1.2 * pitch) << "row " << j;
  }
  const auto [kept, kept_pulses] = take(0);
  EXPECT_EQ(kept.fill_sweeps, 0);
  EXPECT_GE(kept.lost_profiles, 10);
  for (const int j : {40, 41, 42, 43, 44, 100, 252, 253, 254, 255}) EXPECT_FALSE(kept.image.acquired_rows[static_cast<std::size_t>(j)]) << "row " << j;
  EXPECT_LE(kept_pulses, 256u);
}

// scanner.trigger_source: drive_compare. The sweep drive's position compare (the simulated Modbus drive's
// registers 12-19) triggers every row at start + r·pitch, and each profile's pose is its compare position:
// rows land on their row-index line to within the scanner's own noise, where the daemon's polled compare
// puts them up to a pitch beyond. Lost profiles are retaken by a compare over their span.
TEST_F(SimCell, TheDrivesPositionCompareTriggersEveryRowAtItsPosition) {
  sp::TriangleMesh cube = sp::load_mesh(write_cube(dir));
  for (auto& v : cube.vertices) v -= Eigen::Vector3d(25, 25, 0);
  const double L = 60.0, pitch = L / 255.0;
  const sp::IkResult ik = sp::look_at(models.cell, Eigen::Vector3d(25, 0, 25), 160.0, 0.0, 0.0, L);
  ASSERT_TRUE(ik.ok) << ik.why;
  LossyHead head;
  head.inner = make_sim_head(models.sensor, cube, cube.triangles.size(), 7, &models.cell, nullptr);
  head.lose_rows = {40, 41, 42, 43, 44, 100};
  head.sweep = models.cell.axis_index("sweep");
  head.start_mm = ik.q[head.sweep] - 0.5 * L;
  head.pitch_mm = pitch;
  JobSettings s;
  s.scan_speed_mm_s = scan_speed;
  s.drive_compare = true;
  std::atomic<int> stop{0};
  const Acquisition a = acquire_view(io->positioner, head, models.cell, models.sensor, ik.q, L, s, stop);
  EXPECT_EQ(a.lost_profiles, 0);
  EXPECT_EQ(a.fill_sweeps, 1);
  EXPECT_EQ(a.filled_profiles, 6);
  // The sweep's 256 pulses, then the fill's compare over rows 40 … 100 (61), each at its compare position.
  ASSERT_EQ(head.compare_at.size(), 256u + 61u);
  EXPECT_EQ(head.pulses, 256u + 61u);
  for (std::size_t k = 0; k < head.compare_at.size(); ++k) {
    const int row = k < 256 ? static_cast<int>(k) : 40 + static_cast<int>(k - 256);
    EXPECT_NEAR(head.compare_at[k], head.start_mm + row * pitch, 1e-9) << "pulse " << k;
  }
  const sp::RangeImage& img = a.image;
  int checked = 0;
  double worst = 0.0;
  for (int j = 0; j < img.rows; ++j) {
    double y = 0;
    int n = 0;
    for (int i = 0; i < img.columns; ++i)
      if (img.at(i, j).valid()) y += img.at(i, j).camera_mm.y(), ++n;
    if (n < 50) continue;  // past the cube's edge
    worst = std::max(worst, std::abs(y / n - (-0.5 * L + j * pitch)));
    ++checked;
  }
  EXPECT_GT(checked, 150);
  // Measured 0.004 mm (pitch 0.235 mm): the scanner's own noise along the sweep.
  EXPECT_LT(worst, 0.1 * pitch) << "the farthest row's mean y from its compare position (mm)";
}

TEST_F(SimCell, CubeJobMeasuresEverythingTheCellCanMeasure) {
  next_setup_min_area_mm2 = 100.0;  // the daemon's default
  const auto job = submit(write_cube(dir));
  std::atomic<int> stop{0};
  auto r = runner();
  // Done, or stalled on a sliver the rough model's estimate promised but no executed view delivered (the
  // profile positions come from polling the sweep, so the samples differ slightly run to run).
  const JobState end = r.run(job, stop);
  EXPECT_TRUE(end == JobState::done || end == JobState::stalled) << journal->job(job).cause;
  if (::getenv("SCANCELL_TEST_VERBOSE"))
    for (const auto& e : journal->events(job)) std::cerr << e << "\n";
  const JobRecord rec = journal->job(job);
  const auto result = nlohmann::json::parse(rec.result_json);
  // The base (2500 of 15000 mm²) is on the plate: measured coverage of the rough model and the verified m_v
  // against the cube are both near 5/6, and no plan views are left unexecuted.
  EXPECT_NEAR(result["measured_coverage"].get<double>(), 5.0 / 6.0, 0.04);
  EXPECT_NEAR(result["verified_mv"].get<double>(), 5.0 / 6.0, 0.04);
  EXPECT_GT(result["unmeasurable_rows"].get<int>(), 0);
  EXPECT_LT(result["open_area_mm2"].get<double>(), 0.01 * result["rough_area_mm2"].get<double>());
  if (end == JobState::done) {
    EXPECT_EQ(result["open_rows"].get<int>(), 0);
  }
  // The coverage picture: the six views labelled, with a legend and the headline numbers (gnuplot).
  EXPECT_FALSE(result.contains("coverage_png_error")) << result.dump();
  expect_whole_png(result["coverage_png"].get<std::string>(), 1240, 860, 15000);  // flat faces compress well
  // Issue 20, first part: the base is what is left, so the second setup is any other face down (a cube rests
  // on each alike), predicted to measure most of the base's 2500 mm², with a picture of it turned so.
  ASSERT_TRUE(result.contains("next_setup")) << result.dump();
  const auto& next = result["next_setup"];
  ASSERT_TRUE(next.contains("resting_pose")) << next.dump();
  EXPECT_GT(next["down_object"][2].get<double>(), -0.5) << next.dump();  // not the base down again
  EXPECT_GT(next["predicted_gain_mm2"].get<double>(), 0.8 * 2500.0) << next.dump();
  EXPECT_LT(next["predicted_gain_mm2"].get<double>(), next["unmeasured_area_mm2"].get<double>() + 1e-9);
  EXPECT_TRUE(fs::exists(next["picture"].get<std::string>()));
  for (auto p : journal->plans(job)) EXPECT_FALSE(journal->first_unfinished_view(p).has_value());
  EXPECT_EQ(stored_views(job), static_cast<std::size_t>(result["views"].get<int>()));
  EXPECT_TRUE(journal->check().empty());
  // The inspection report (issue 19): cloud and model against the submitted cube, signed; the targets
  // on the seen part are a mean within 0.03 mm and 95 % within 0.1 mm.
  {
    std::ifstream rf(result["report"].get<std::string>());
    ASSERT_TRUE(rf) << result.dump();
    const auto report = nlohmann::json::parse(rf);
    EXPECT_EQ(report["reference_kind"], "submitted mesh");
    EXPECT_LT(std::abs(report["cloud"]["mean_mm"].get<double>()), 0.03) << report.dump();
    EXPECT_LT(report["cloud"]["p95_abs_mm"].get<double>(), 0.1) << report.dump();
    EXPECT_LT(std::abs(report["model"]["mean_mm"].get<double>()), 0.03) << report.dump();
    EXPECT_LT(report["model"]["p95_abs_mm"].get<double>(), 0.1) << report.dump();
    EXPECT_EQ(report["cloud"]["points"].get<std::size_t>(), result["cloud_points"].get<std::size_t>());
    // Its picture: a whole PNG of 1600 x 820 beside it, named by the report and the result.
    ASSERT_TRUE(report.contains("deviation_png")) << report.dump();
    EXPECT_EQ(result["deviation_png"], report["deviation_png"]);
    expect_whole_png(report["deviation_png"].get<std::string>(), 1600, 820, 40000);
    std::cout << "report: cloud " << report["cloud"].dump() << "\nmodel " << report["model"].dump() << "\n";
  }
  // The lifecycle in order, journalled.
  const auto ev = journal->events(job);
  auto at = [&](const std::string& s) {
    return std::find_if(ev.begin(), ev.end(), [&](const std::string& e) { return e.rfind(s, 0) == 0; }) - ev.begin();
  };
  EXPECT_LT(at("planning"), at("executing"));
  EXPECT_LT(at("executing"), at("verifying"));
  EXPECT_LT(at("verifying"), at("done"));
  // Every stored scan is a range image whose samples lie on the cube (object frame, placed on the plate); the
  // fullest holds a large part of a face (which view comes first depends on the travel order).
  std::size_t fullest = 0;
  for (const auto& scan : journal->scans(journal->plans(job).front())) {
    const sp::RangeImage img = sp::range_image_from_ply(journal->read_scan(scan), scan.file);
    std::size_t on_cube = 0;
    for (const auto& s : img.samples)
      if (s.valid()) on_cube += (s.object_mm.array() > -0.5f).all() && (s.object_mm.array() < 50.5f).all();
    EXPECT_GT(on_cube, 0.99 * static_cast<double>(img.valid_count())) << scan.file;
    fullest = std::max(fullest, img.valid_count());
  }
  EXPECT_GT(fullest, 10000u);
  // The product (issue 19): cloud.ply holds every spec-compliant registered sample, on the cube, with
  // normals facing out of it (towards the scanner), at least the spec's 2 samples/mm² over the 5 faces seen.
  const std::string cloud = result["cloud"].get<std::string>();
  std::ifstream f(cloud, std::ios::binary);
  ASSERT_TRUE(f) << cloud;
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const std::size_t body = bytes.find("end_header\n") + 11;
  const std::size_t n = result["cloud_points"].get<std::size_t>();
  ASSERT_NE(bytes.find("element vertex " + std::to_string(n) + "\n"), std::string::npos);
  ASSERT_EQ(bytes.size() - body, n * 36);
  EXPECT_GT(static_cast<double>(n), 2.0 * 12500.0);
  std::size_t off_face = 0, with_normal = 0, outward = 0;
  for (std::size_t k = 0; k < n; ++k) {
    float v[9];
    std::memcpy(v, bytes.data() + body + 36 * k, sizeof v);
    const Eigen::Vector3d p(v[0], v[1], v[2]), nrm(v[3], v[4], v[5]);
    // Nearest face of [0, 50]^3 and its outward normal.
    double best = 1e9;
    Eigen::Vector3d out = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a)
      for (const double side : {0.0, 50.0}) {
        const double d = std::abs(p[a] - side);
        if (d < best) {
          best = d;
          out = Eigen::Vector3d::Zero();
          out[a] = side == 0.0 ? -1.0 : 1.0;
        }
      }
    off_face += best > 3.0 * 0.050;  // 3 x the precision spec
    if (nrm.norm() > 0.5) {
      ++with_normal;
      outward += nrm.dot(out) > 0.9;
    }
  }
  EXPECT_LT(static_cast<double>(off_face), 0.001 * static_cast<double>(n));
  // A sample beside a lost profile or the image's edge has no normal (0 0 0): 95 % have one on an idle
  // machine, 90 % measured beside the kill loop.
  EXPECT_GT(static_cast<double>(with_normal), 0.8 * static_cast<double>(n));
  EXPECT_GT(static_cast<double>(outward), 0.98 * static_cast<double>(with_normal));
  // The surface model: on the cube's faces (its vertices' distance to the nearest face), open where the base
  // stood on the plate (never measured: left a hole, not closed by invention).
  std::ifstream mf(result["model"].get<std::string>(), std::ios::binary);
  ASSERT_TRUE(mf);
  const std::string mb((std::istreambuf_iterator<char>(mf)), std::istreambuf_iterator<char>());
  const std::size_t mv = std::stoul(mb.substr(mb.find("element vertex ") + 15));
  const std::size_t mbody = mb.find("end_header\n") + 11;
  double ss = 0.0;
  std::size_t far = 0;
  for (std::size_t k = 0; k < mv; ++k) {
    float v[3];
    std::memcpy(v, mb.data() + mbody + 16 * k, sizeof v);
    double best = 1e9;
    for (int a = 0; a < 3; ++a) best = std::min({best, std::abs(v[a] - 0.0), std::abs(v[a] - 50.0)});
    ss += best * best;
    far += best > 0.15;
  }
  const double model_rms = std::sqrt(ss / static_cast<double>(mv));
  std::cout << "cube job: cloud " << n << " points, model " << result["model_triangles"] << " triangles, "
            << result["model_open_edges"] << " open edges, distance to the cube rms " << model_rms << " mm, "
            << far << " of " << mv << " vertices over 0.15 mm\n";
  EXPECT_GT(mv, 10000u);
  EXPECT_LT(model_rms, 0.05);
  EXPECT_LT(static_cast<double>(far), 0.01 * static_cast<double>(mv));
  EXPECT_GT(result["model_open_edges"].get<int>(), 100);
}

// Issue 15, the closed loop: the submitted mesh has a block on top that the real object lacks. Every round
// predicts the block's rows measurable and none is ever measured. The loop must not chase them round after
// round to jobs.max_rounds: after jobs.retire_after_failures (3) rounds, or at once when a replanning round
// measures nothing new or under 20 % of its prediction, they are retired as needing attention, the rounds
// that delivered under 20 % of their prediction are named, and the job stops.
TEST_F(SimCell, RowsPredictedTwiceAndNeverMeasuredAreRetiredNotChased) {
  sp::TriangleMesh phantom;
  const sp::TriangleMesh cube = sp::load_mesh(write_cube(dir));
  sp::TriangleMesh block;
  block.vertices = {{15, 15, 50}, {35, 15, 50}, {35, 35, 50}, {15, 35, 50}, {15, 15, 75}, {35, 15, 75}, {35, 35, 75}, {15, 35, 75}};
  block.triangles = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                     {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
  phantom = cube;
  sp::append_mesh(phantom, sp::refine_edges(block, 6.0));
  sp::write_off(phantom, (dir / "phantom.off").string());
  max_rounds = 6;
  // Triggered by the drive's position compare: with the polled compare, where a loaded machine lands each
  // profile decides which real-wall rows fail twice, and an ASan CI run stalled on "replan adds nothing"
  // (13 measurable rows left) before any row was retired. Load is SimCell.FillSweeps…'s subject.
  drive_compare = true;
  JobRequest req;
  req.mesh = (dir / "phantom.off").string();
  req.truth = (dir / "cube.off").string();
  req.rough_vertices = 600;
  validate_request(req);
  const auto job = journal->create_job(req.mesh, req.to_json().dump());
  std::atomic<int> stop{0};
  auto r = runner();
  EXPECT_EQ(r.run(job, stop), JobState::stalled) << journal->job(job).cause;
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  for (const auto& e : journal->events(job))
    if (e.rfind("round ", 0) == 0 || e.rfind("stalled", 0) == 0 || e.find("fill") != std::string::npos) std::cout << e << "\n";
  EXPECT_LT(result["rounds"].get<int>(), 6);  // stopped before max_rounds
  EXPECT_GT(result["needs_attention_rows"].get<int>(), 0);
  // The stop names the same rows the result counts.
  EXPECT_THAT(journal->job(job).cause,
              HasSubstr(std::to_string(result["needs_attention_rows"].get<int>()) + " rows ("));
  EXPECT_THAT(journal->job(job).cause, HasSubstr("need attention"));
  // What needs attention is chiefly the block that is not there (a sliver of the real walls at the plate,
  // which the rough model promises and no view delivers, may join it).
  std::ifstream f(result["needs_attention_file"].get<std::string>());
  std::string line;
  std::size_t rows = 0, on_block = 0;
  double area = 0.0, block_area = 0.0;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    double x, y, z, nx, ny, nz, a;
    ls >> x >> y >> z >> nx >> ny >> nz >> a;
    ++rows;
    area += a;
    if (z > 49.0 && x > 13 && x < 37 && y > 13 && y < 37) ++on_block, block_area += a;
  }
  EXPECT_EQ(rows, result["needs_attention_rows"].get<std::size_t>());
  // (On a slow build the polled sweep misses profiles, and real-wall rows may fail twice as well.)
  EXPECT_GE(on_block, 8u);
  EXPECT_GT(block_area, 1000.0);  // of the block's 2400 mm², its top and walls above the cube
  EXPECT_GT(block_area, 0.5 * area);
  EXPECT_NEAR(area, result["needs_attention_area_mm2"].get<double>(), 1e-6 * area + 1e-9);
  for (std::size_t k = 0; k < result["round_gains"].size(); ++k) {
    const auto& g = result["round_gains"][k];
    // A round named under 20 % is one that realized under 20 %, and a replanning round that did is the last:
    // the loop stops rather than repeat it (issue 15).
    EXPECT_EQ(g["under_20_percent"].get<bool>(), g["realized_gain_mm2"].get<double>() < 0.2 * g["predicted_gain_mm2"].get<double>());
    if (k > 0 && g["under_20_percent"].get<bool>()) {
      EXPECT_EQ(k + 1, result["round_gains"].size()) << result["round_gains"].dump();
    }
  }
  ASSERT_EQ(result["round_gains"].size(), static_cast<std::size_t>(result["rounds"].get<int>()));
  EXPECT_GT(result["round_gains"][0]["realized_gain_mm2"].get<double>(), 5000.0);  // the cube's walls and top
}

TEST_F(SimCell, DriveFaultFaultsTheJobAndResumeFinishesWithoutRepeatingAView) {
  // On a loaded host (ASan, two test processes on two cores) most sweeps lose profiles; the rows they passed
  // are aimed at again rather than retired, which may take a round more than the default four.
  max_rounds = 6;
  const auto job = submit(write_cube(dir));
  std::atomic<int> stop{0};
  auto r = runner();
  // The lift drive raises a following error on its next move, a few views in. The injector gives up when the
  // run ends first (a job that ended, or faulted otherwise, before two views were stored): the test then fails
  // on the state below instead of hanging in join (it hung once under ASan in CI, session 26).
  std::atomic<bool> ran{false};
  std::thread injector([&] {
    while (stored_views(job) < 2 && !ran) std::this_thread::sleep_for(5ms);
    if (!ran) io->sim_drives[2]->inject(dr::sim::ModbusFault::following_error);
  });
  const JobState s = r.run(job, stop);
  ran = true;
  injector.join();
  ASSERT_EQ(s, JobState::faulted) << journal->job(job).cause << " (" << stored_views(job) << " views stored)";
  EXPECT_THAT(journal->job(job).cause, HasSubstr("lift"));
  const std::size_t before = stored_views(job);
  EXPECT_GE(before, 2u);
  // Clear the fault, resume: the job continues at its first unfinished view and runs to its end (done, or
  // stalled on a sliver the rough model promised and no view delivered, as in the test above).
  io->sim_drives[2]->inject(dr::sim::ModbusFault::none);
  bring_up(*io, models.cell, 10000ms);
  EXPECT_EQ(r.run(job, stop), JobState::faulted);  // a faulted job is not run until it is resumed
  journal->set_state(job, JobState::queued, "resumed");  // what the daemon's resume does
  const JobState end = r.run(job, stop);
  EXPECT_TRUE(end == JobState::done || end == JobState::stalled) << journal->job(job).cause;
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  if (::getenv("SCANCELL_TEST_VERBOSE"))
    for (const auto& e : journal->events(job)) std::cerr << e << "\n";
  EXPECT_LT(result["open_area_mm2"].get<double>(), 0.01 * result["rough_area_mm2"].get<double>());
  EXPECT_TRUE(journal->check().empty());
  const auto ev = journal->events(job);
  EXPECT_TRUE(std::any_of(ev.begin(), ev.end(), [&](const std::string& e) {
    return e.find("resuming at view " + std::to_string(before + 1)) != std::string::npos;
  })) << "no resume event at view " << before + 1;
}

TEST_F(SimCell, PauseStopsAtASafePointAndAbortEndsTheJob) {
  const auto job = submit(write_cube(dir));
  std::atomic<int> stop{0};
  auto r = runner();
  std::thread pauser([&] {
    while (stored_views(job) < 1) std::this_thread::sleep_for(2ms);
    stop = static_cast<int>(StopRequest::pause);
  });
  EXPECT_EQ(r.run(job, stop), JobState::paused);
  pauser.join();
  EXPECT_EQ(journal->job(job).state, JobState::paused);
  const std::size_t stored = stored_views(job);
  EXPECT_TRUE(journal->check().empty());
  // Issue 16, suspected race 2: a job paused just before the runner starts it is not run (the runner used to
  // run it, and the pause was lost).
  stop = 0;
  EXPECT_EQ(r.run(job, stop), JobState::paused);
  EXPECT_EQ(stored_views(job), stored);
  journal->set_state(job, JobState::queued, "resumed");  // what the daemon's resume does
  stop = static_cast<int>(StopRequest::abort);
  EXPECT_EQ(r.run(job, stop), JobState::aborted);
  EXPECT_EQ(stored_views(job), stored);  // nothing half-stored, nothing lost
  EXPECT_TRUE(finished(journal->job(job).state));
}

// Issue 16: an abort or pause during planning took effect only after the plan (over 2 minutes on a big
// object). Planning stops at its next stage boundary: a pause given before the first plan leaves the job
// paused with no plan journalled, and an abort ends it the same way.
TEST_F(SimCell, PauseAndAbortStopPlanningWithoutWaitingForThePlan) {
  const auto job = submit(write_cube(dir));
  std::atomic<int> stop{static_cast<int>(StopRequest::pause)};
  auto r = runner();
  EXPECT_EQ(r.run(job, stop), JobState::paused);
  EXPECT_THAT(journal->job(job).cause, HasSubstr("during planning"));
  EXPECT_TRUE(journal->plans(job).empty());
  journal->set_state(job, JobState::queued, "resumed");
  stop = static_cast<int>(StopRequest::abort);
  EXPECT_EQ(r.run(job, stop), JobState::aborted);
  EXPECT_TRUE(journal->plans(job).empty());
  EXPECT_EQ(stored_views(job), 0u);
}

TEST_F(SimCell, RegistrationPutsSamplesWhereTheyReallyAreUnderPoseError) {
  // The positioner misses by σ_p 0.5 mm, σ_a 0.5° per move (issue 9's figure). The job is given a coarse
  // mesh of the object (1500 vertices, what a rough scan or an old model would be); the truth is the fine
  // one. Without registration the samples sit where the cell model put the camera; with it, where the
  // surface really is (the simulator knows each sample's true hit point). One plan round each.
  SimTruth t;
  t.pose_error = {0.5, 0.5 * M_PI / 180.0, 0.5 * M_PI / 180.0};
  t.seed = 5;
  truth = t;
  max_rounds = 1;
  // At 400 mm/s a loaded build's polled sweep loses profiles (coverage fell from 0.85 to 0.66 beside the
  // kill loop), and the measured/verified comparison below drifted past 1 % on the holes' edges; this test is
  // about registration, so it sweeps at half speed.
  scan_speed = 200.0;
  sp::TriangleMesh fine = sp::load_mesh(src("tests/data/mushroom.off"));
  sp::apply_scale(fine, sp::fit_scale(fine, 100.0));
  sp::write_off(fine, (dir / "fine.off").string());
  sp::write_off(sp::decimate(fine, 1500), (dir / "coarse.off").string());
  auto submit_coarse = [&] {
    JobRequest r;
    r.mesh = (dir / "coarse.off").string();
    r.truth = (dir / "fine.off").string();
    // Rows of ~10 mm²: a 600-row model's 100 mm² rows sit at the 90 % fill threshold and flip, run to run,
    // by a percent of the area each.
    r.rough_vertices = 2000;
    validate_request(r);
    return journal->create_job(r.mesh, r.to_json().dump());
  };
  std::size_t refused = 0, views = 0;
  auto count_refused = [&](std::int64_t job) {
    for (auto p : journal->plans(job))
      for (const auto& sc : journal->scans(p)) {
        ++views;
        if (!sc.note.empty()) {  // a refused registration: stored, flagged, not counted
          ++refused;
          std::cout << "view " << sc.view << ": " << sc.note << "\n";
        }
      }
  };
  std::atomic<int> stop{0};
  const auto job = submit_coarse();
  auto r = runner();
  r.run(job, stop);
  count_refused(job);
  // Each counted view's samples against where they really are: over the whole 3-D offset, and across the true
  // surface; and whether its shape left a direction as positioned (the job's event for the view says so).
  struct ViewError {
    double ss = 0.0, ss_across = 0.0;
    std::size_t n = 0;
  };
  auto view_errors = [&](std::int64_t of, bool with_free_directions) {
    const std::vector<std::string> ev = journal->events(of);
    ViewError out;
    for (auto p : journal->plans(of))
      for (const auto& sc : journal->scans(p)) {
        const std::string head = "view " + std::to_string(sc.view + 1) + "/";
        const bool free = std::any_of(ev.begin(), ev.end(), [&](const std::string& e) {
          return e.rfind(head, 0) == 0 && e.find("directions left as positioned") != std::string::npos;
        });
        if (!sc.note.empty() || free != with_free_directions) continue;
        const sp::RangeImage img = sp::range_image_from_ply(journal->read_scan(sc), sc.file);
        for (std::size_t k = 0; k < img.samples.size(); ++k) {
          if (!img.samples[k].valid() || img.truth[k].triangle >= fine.triangles.size()) continue;
          const Eigen::Vector3d e = (img.samples[k].object_mm - img.truth[k].object_mm).cast<double>();
          const auto& tri = fine.triangles[img.truth[k].triangle];
          const Eigen::Vector3d n =
              (fine.vertices[tri[1]] - fine.vertices[tri[0]]).cross(fine.vertices[tri[2]] - fine.vertices[tri[0]]).normalized();
          out.ss += e.squaredNorm();
          out.ss_across += std::pow(e.dot(n), 2);
          ++out.n;
        }
      }
    return out;
  };
  register_views = false;
  const auto job2 = submit_coarse();
  auto r2 = runner();
  r2.run(job2, stop);
  const auto rw = nlohmann::json::parse(journal->job(job).result_json), ro = nlohmann::json::parse(journal->job(job2).result_json);
  const double with = rw["sample_error_rms_mm"], without = ro["sample_error_rms_mm"];
  const double m_with = rw["measured_coverage"], v_with = rw["verified_coverage"];
  const double m_without = ro["measured_coverage"], v_without = ro["verified_coverage"];
  std::cout << "sample position error RMS: registered " << with << " mm, unregistered " << without << " mm; coverage measured/verified "
            << m_with << "/" << v_with << " (m_v " << rw["verified_mv"] << ") vs " << m_without << "/" << v_without << " (m_v "
            << ro["verified_mv"] << "); across the surface " << rw["sample_normal_error_rms_mm"] << " vs " << ro["sample_normal_error_rms_mm"]
            << " mm; samples off spec " << rw["samples_off_spec"] << " vs " << ro["samples_off_spec"] << "\n";
  EXPECT_LE(refused, views / 5) << refused << " of " << views << " registrations refused";
  // The product says what it left out (issue 19): the refused views are stored but not in the cloud or model.
  EXPECT_EQ(rw["product_views"].get<std::size_t>(), views - refused);
  if (refused > 0) {
    EXPECT_THAT(rw["product_note"].get<std::string>(), HasSubstr(std::to_string(refused) + " of " + std::to_string(views) + " views"));
  } else {
    EXPECT_FALSE(rw.contains("product_note"));
  }
  EXPECT_GT(without, 1.0);  // the pose error is there
  // and registration takes it out where the view's shape fixes it: what is left is range noise and the coarse
  // mesh's bias. A view that sees a surface of revolution (the cap from above) keeps the turn about its axis
  // as positioned (thesis 8.2): that error lies along the surface, not across it.
  const ViewError fixed = view_errors(job, false), slid = view_errors(job, true);
  ASSERT_GT(fixed.n, 0u);
  std::cout << "views fixed in all six directions: " << fixed.n << " samples, RMS " << std::sqrt(fixed.ss / fixed.n)
            << " mm; with a direction left as positioned: " << slid.n << " samples, RMS "
            << (slid.n ? std::sqrt(slid.ss / slid.n) : 0.0) << " mm, across the surface "
            << (slid.n ? std::sqrt(slid.ss_across / slid.n) : 0.0) << " mm\n";
  EXPECT_LT(std::sqrt(fixed.ss / fixed.n), 0.1);
  if (slid.n > 0 && slid.ss / slid.n > 0.01) {
    EXPECT_LT(slid.ss_across, 0.1 * slid.ss);  // under a third of its RMS
  }
  // What the daemon measured (its samples where it stored them) is what the truth positions measure, counting
  // only samples stored within 3 × the precision spec of where they really are.
  EXPECT_NEAR(m_with, v_with, 0.01);
  // Unregistered, the daemon believes much the same coverage, but most of its samples are stored farther
  // across the surface than the spec allows: it would overstate the coverage by tens of percent.
  EXPECT_GT(m_without, 0.5);
  EXPECT_LT(v_without, m_without - 0.2);
  EXPECT_LT(rw["sample_normal_error_rms_mm"].get<double>(), 0.05);
  EXPECT_GT(ro["sample_normal_error_rms_mm"].get<double>(), 0.3);
  // One round allowed: the job ends after it, either with every row the cell can measure measured (since
  // session 47's open-direction credit, round 0 of this coarse mushroom does so) or at jobs.max_rounds,
  // naming the rows that need attention as every stall does (none retired after a single round). Nothing
  // else: not a stall of a round that measured nothing, nor one that fell short of its prediction.
  EXPECT_THAT(journal->job(job).cause, ::testing::AnyOf(HasSubstr("spec met: measured "),
                                                        HasSubstr("after 1 rounds: 0 rows (0.0 mm2) need attention: measured ")));
}

TEST_F(SimCell, PlacementAutoStandsTheObjectSoTheCellMeasuresMore) {
  // An 80 × 40 × 20 mm bar given lying flat: the plate would hide its 3200 mm² base, 29 % of its 11200 mm².
  // With placement auto the job plans its four most probable resting poses (placement.candidates; the
  // 40 × 20 ends come 5th and 6th), stands it on an 80 × 20 side (14 % hidden), the simulated cell places
  // it so, and the verified m_v of the whole surface shows it.
  JobRequest r;
  r.mesh = write_box(dir, Eigen::Vector3d(80, 40, 20), "bar.off");
  r.rough_vertices = 600;
  r.placement = "auto";
  validate_request(r);
  const auto job = journal->create_job("bar", r.to_json().dump());
  max_rounds = 2;
  std::atomic<int> stop{0};
  auto runner_ = runner();
  const JobState end = runner_.run(job, stop);
  ASSERT_TRUE(end == JobState::done || end == JobState::stalled) << journal->job(job).cause;
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  ASSERT_TRUE(result.contains("placement")) << result.dump();
  const auto& rot = result["placement"]["object_to_table_row_major"];
  // The object's y axis (its 40 mm width) is the table's vertical: the bar stands on an 80 × 20 side.
  EXPECT_GT(std::abs(rot[7].get<double>()), 0.9999) << result["placement"].dump();
  EXPECT_THAT(result["placement"]["reason"].get<std::string>(), HasSubstr("as given"));
  const auto ev = journal->events(job);
  EXPECT_TRUE(std::any_of(ev.begin(), ev.end(), [](const std::string& e) { return e.rfind("placement: ", 0) == 0; }));
  std::cout << "placement auto: " << result["placement"]["reason"] << ", verified m_v " << result["verified_mv"] << "\n";
  EXPECT_GT(result["verified_mv"].get<double>(), 1.0 - 1600.0 / 11200 - 0.06);  // as given it could not pass 0.714
  // A bounding-box job already stands on the table: auto is refused there, and an unknown mode anywhere.
  JobRequest b;
  b.bbox_mm = Eigen::Vector3d(60, 60, 60);
  b.truth = r.mesh;
  b.placement = "auto";
  EXPECT_THROW(validate_request(b), std::invalid_argument);
  r.placement = "upside_down";
  EXPECT_THROW(validate_request(r), std::invalid_argument);
}

TEST_F(SimCell, FromABoundingBoxRoughScanThenPlanAndMeasure) {
  // Nothing known but the object's size: the rough scan's exploration views are fused into a closed rough
  // model standing on the table (the underside hypothetical), then the usual plan-execute-replan loop.
  const std::string cube = write_cube(dir);
  // The rough scan's long sweeps at half the speed, triggered by the drive's position compare: with the
  // daemon's polled compare, where a loaded machine lands each profile moves the fused rough model and so
  // every plan after it (an ASan CI run read verified m_v 0.683 where quiet runs read 0.82-0.86). How the
  // polled compare copes with load is SimCell.FillSweeps…'s business, not this test's.
  scan_speed = 200.0;
  drive_compare = true;
  JobRequest r;
  r.bbox_mm = Eigen::Vector3d(60, 60, 60);
  r.truth = cube;
  r.rough_vertices = 600;
  validate_request(r);
  const auto job = journal->create_job("bbox", r.to_json().dump());
  std::atomic<int> stop{0};
  auto runner_ = runner();
  const JobState end = runner_.run(job, stop);
  ASSERT_TRUE(end == JobState::done || end == JobState::stalled) << journal->job(job).cause;
  const auto ev = journal->events(job);
  EXPECT_TRUE(std::any_of(ev.begin(), ev.end(), [](const std::string& e) { return e.rfind("rough_scanning", 0) == 0; }));
  // Planned as a model that carries error (docs/planner.md: open-direction views keep their margin on every row).
  EXPECT_TRUE(std::any_of(ev.begin(), ev.end(), [](const std::string& e) {
    return e.find("rough model: planned as off the true surface by 0.40 mm (jobs.fused_model_sigma_mm)") != std::string::npos;
  }));
  // The rough model: within 1.5 voxels of the cube's faces where measured, closed underneath.
  const sp::TriangleMesh rough = sp::load_mesh(dir / "data" / "jobs" / std::to_string(job) / "rough.off");
  double worst = 0.0;
  for (const auto& p : rough.vertices) {
    const Eigen::Vector3d q = p - Eigen::Vector3d(-25, -25, 0);  // the cube stands centred on the table
    const Eigen::Vector3d hi = Eigen::Vector3d::Constant(50) - q;
    worst = std::max(worst, std::min({std::abs(q.x()), std::abs(q.y()), std::abs(q.z()), std::abs(hi.x()), std::abs(hi.y()), std::abs(hi.z())}));
  }
  EXPECT_LT(worst, 2.5);
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  if (::getenv("SCANCELL_TEST_VERBOSE"))
    for (const auto& e : journal->events(job)) std::cerr << e << "\n";
  std::cout << "bbox job: rough model " << rough.vertices.size() << " vertices (worst " << worst << " mm from the cube), " << result["views"]
            << " views, measured " << result["measured_coverage"] << ", verified m_v " << result["verified_mv"] << "\n";
  EXPECT_NEAR(result["verified_mv"].get<double>(), 5.0 / 6.0, 0.06);
  // The underside the rough scan could not see is flagged as a guess in the rough model's rows, and kept
  // apart from the seen surface in the verdict.
  std::cout << "hypothetical rows " << result["hypothetical_rows"] << ", unmeasured " << result["hypothetical_unmeasured_rows"] << "\n";
  EXPECT_GT(result["hypothetical_rows"].get<int>(), 5);
  // The rough model against the cube (issue 9's quality check): the seen part within the 2.5 mm found above,
  // the whole — the guessed underside too — within 2 voxels, normals mostly right (edges are rounded).
  const auto& q = result["rough_model"];
  std::cout << "rough model vs truth: " << q.dump() << "\n";
  EXPECT_LT(q["seen_rough_to_fine_max_mm"].get<double>(), 2.5);
  EXPECT_LT(q["seen_rough_to_fine_mean_mm"].get<double>(), 0.5);
  EXPECT_LT(q["hausdorff_mm"].get<double>(), 3.0);
  EXPECT_LT(q["seen_normal_error_mean_rad"].get<double>(), 0.2);
  EXPECT_TRUE(fs::exists(dir / "data" / "jobs" / std::to_string(job) / "rough.hypothetical.xyz"));
  EXPECT_TRUE(journal->check().empty());
}

TEST_F(SimCell, TwoSetupsTurnThePartOverAlignItAndMeasureWhatRestedOnThePlate) {
  // Issue 20. The elephant (100 mm) stands on its feet: setup 1 cannot measure what rests on the plate or
  // faces it. The job then waits for the operator with the resting pose to use; the simulated operator puts
  // it down off by up to 8 mm and 12° on the plate; setup 2 explores it, aligns the samples to the model
  // and measures the rest. A stop during the exploration resumes without repeating a stored view.
  JobRequest r;
  r.mesh = src("tests/data/elephant.off");
  r.fit_mm = 100.0;
  r.rough_vertices = 600;
  r.setups = 2;
  validate_request(r);
  const auto job = journal->create_job("elephant", r.to_json().dump());
  max_rounds = 1;  // one round per setup: the setups are what is tested
  next_setup_min_area_mm2 = 100.0;
  sim_placement_error_mm = 8.0;
  sim_placement_error_rad = 0.21;
  std::atomic<int> stop{0};
  {
    auto runner_ = runner();
    ASSERT_EQ(runner_.run(job, stop), JobState::awaiting_operator) << journal->job(job).cause;
  }
  const auto waiting = nlohmann::json::parse(journal->job(job).result_json);
  EXPECT_EQ(waiting["state"], "awaiting_operator");
  EXPECT_THAT(waiting["instruction"].get<std::string>(), HasSubstr("scancellctl continue " + std::to_string(job)));
  EXPECT_THAT(journal->job(job).cause, HasSubstr("turn the part over"));
  const double after_setup1 = waiting["measured_coverage"].get<double>();
  // Not runnable until the operator confirms.
  EXPECT_EQ(runner().run(job, stop), JobState::awaiting_operator);

  // The operator's continue (what the daemon's `continue` does), then a stop at the 4th exploration view.
  journal->set_state(job, JobState::queued, "continued");
  on_report = [&](const Progress& p) {
    if (p.event.rfind("setup 2 exploration 4/", 0) == 0) stop = static_cast<int>(StopRequest::shutdown);
  };
  { EXPECT_NE(runner().run(job, stop), JobState::done); }
  on_report = nullptr;
  stop = 0;
  std::int64_t exploration = 0;
  for (const auto& [plan, round] : journal->plan_rounds(job))
    if (round == -2) exploration = plan;
  ASSERT_GT(exploration, 0);
  const std::size_t explored_before = journal->scans(exploration).size();
  EXPECT_GE(explored_before, 3u);
  EXPECT_LT(explored_before, journal->views(exploration).size());

  const JobState end = runner().run(job, stop);
  ASSERT_TRUE(end == JobState::done || end == JobState::stalled) << journal->job(job).cause;
  EXPECT_EQ(journal->scans(exploration).size(), journal->views(exploration).size());  // each view stored once
  const auto result = nlohmann::json::parse(journal->job(job).result_json);
  ASSERT_TRUE(result.contains("setups")) << result.dump();
  ASSERT_EQ(result["setups"].size(), 2u) << result["setups"].dump();
  const auto& a = result["setups"][1]["alignment"];
  std::cout << "two setups: measured " << after_setup1 << " -> " << result["measured_coverage"] << ", verified m_v "
            << result["verified_mv"] << ", alignment " << a.dump() << "\n";
  ASSERT_TRUE(a["ok"].get<bool>()) << a.dump();
  EXPECT_GT(a["sim_operator_turn_deg"].get<double>(), 1.0);  // the operator was off, and the alignment found it
  // Issue 20's target: the placement found to 0.05 mm and 0.05° (0.011 mm, 0.004° since the fit moves the
  // part only as the plate lets it; 0.054 mm, 0.036° when it could also tilt and lift).
  EXPECT_LT(a["sim_residual_mm"].get<double>(), 0.05);
  EXPECT_LT(a["sim_residual_deg"].get<double>(), 0.05);
  EXPECT_LT(std::abs(a["tilt_rad"].get<double>()), 1e-6);  // the plate fixes the tilt (4e-8 rad is rounding over the ICP steps)
  EXPECT_GT(result["setups"][1]["views"].get<int>(), 0);
  // What setup 2 measured is where it is: the views registered and the ground truth agrees.
  EXPECT_GT(result["measured_coverage"].get<double>(), after_setup1 + 0.02);
  EXPECT_GT(result["verified_mv"].get<double>(), 0.95);
  // And against the truth: setup 1 ended lower, by what rested on the plate.
  ASSERT_TRUE(result["setups"][0].contains("verified_mv_at_end")) << result["setups"].dump();
  EXPECT_LT(result["setups"][0]["verified_mv_at_end"].get<double>(), result["verified_mv"].get<double>() - 0.02);
}

TEST_F(SimCell, ASetupThatCannotBeAlignedIsRefusedAndTheFirstSetupsProductKept) {
  // A tube looks the same turned about its axis: stood on its other end, the exploration cannot tell how the
  // operator turned it, so nothing of the new setup may be merged. The job stalls naming why and hands over
  // what setup 1 measured.
  const fs::path tube = dir / "tube.off";
  sp::write_off(sp::cylinder_with_bore(60, 30, 50, 3.0), tube.string());
  JobRequest r;
  r.mesh = tube.string();
  r.rough_vertices = 400;
  r.setups = 2;
  validate_request(r);
  const auto job = journal->create_job("tube", r.to_json().dump());
  max_rounds = 1;
  next_setup_min_area_mm2 = 100.0;
  sim_placement_error_mm = 5.0;
  sim_placement_error_rad = 0.3;
  std::atomic<int> stop{0};
  ASSERT_EQ(runner().run(job, stop), JobState::awaiting_operator) << journal->job(job).cause;
  const double after_setup1 = nlohmann::json::parse(journal->job(job).result_json)["measured_coverage"].get<double>();
  journal->set_state(job, JobState::queued, "continued");
  EXPECT_EQ(runner().run(job, stop), JobState::stalled);
  const JobRecord rec = journal->job(job);
  EXPECT_THAT(rec.cause, HasSubstr("setup 2: the part as put down could not be aligned to the model so far, so nothing of it was merged"));
  const auto result = nlohmann::json::parse(rec.result_json);
  std::cout << "tube, setup 2: " << rec.cause << "\n";
  EXPECT_DOUBLE_EQ(result["measured_coverage"].get<double>(), after_setup1);  // nothing of setup 2 counted
  ASSERT_TRUE(result.contains("cloud")) << result.dump();
  EXPECT_TRUE(fs::exists(result["cloud"].get<std::string>()));
  ASSERT_EQ(result["setups"].size(), 2u);
  EXPECT_EQ(result["setups"][1]["views"].get<int>(), 0);
}

TEST(JobRequest, BadInputIsRefusedNamingTheFile) {
  JobRequest r;
  r.mesh = src("../shared/bad-inputs/does-not-exist.stl");
  EXPECT_THROW(validate_request(r), scancell::MeshError);
  r.mesh = src("tests/data/mushroom.off");
  r.fit_mm = -3;
  EXPECT_THROW(validate_request(r), std::invalid_argument);
  r.fit_mm = 200;
  r.spec = src("config/sensors/line-scan-thesis.yaml");  // not a spec
  EXPECT_THROW(validate_request(r), scancell::ConfigError);
  // Issue 16, lesser findings: fit_mm was unchecked for bounding-box jobs, and mesh with bbox_mm was refused
  // for something else.
  auto refusal = [](const JobRequest& q) {
    try {
      validate_request(q);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("<accepted>");
  };
  JobRequest b;
  b.bbox_mm = Eigen::Vector3d(100, 100, 50);
  b.fit_mm = -5;
  EXPECT_EQ(refusal(b), "submit: 'fit_mm' must be > 0");
  b.fit_mm = 0;
  b.mesh = src("tests/data/mushroom.off");
  EXPECT_THAT(refusal(b), HasSubstr("'mesh' and 'bbox_mm' both given"));
}

}  // namespace
}  // namespace scancell::daemon
