// The GenICam scanner driver against a genuine GigE Vision device on loopback: Aravis' ArvGvFakeCamera
// (GVCP control, GVSP stream over UDP) with scancell's GenICam XML, fed by the virtual scanner at the pose
// of each trigger pulse (drivers/sim/sim_gige_scanner). Nothing in between is mocked.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>

#include "drivers/genicam/genicam_scanner.hpp"
#include "drivers/sim/sim_gige_scanner.hpp"
#include "planner/config.hpp"

namespace dr = scancell::drivers;
namespace sp = scancell::planner;
using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {

struct Cell {
  // A plane at z = 0; the camera 200 mm above looking down, swept 0.5 mm along its y per pulse.
  sp::SensorModel sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  sp::TriangleMesh plane;
  std::atomic<double> sweep{0.0};
  std::unique_ptr<dr::SimGigeScanner> device;
  dr::SimGigeOptions options;
  explicit Cell(dr::SimGigeOptions o = {}) : options(std::move(o)) {
    plane.vertices = {{-300, -300, 0}, {300, -300, 0}, {300, 300, 0}, {-300, 300, 0}};
    plane.triangles = {{0, 1, 2}, {0, 2, 3}};
    restart();
  }
  /// The device (again): a scanner powered up.
  void restart() {
    device.reset();
    device = std::make_unique<dr::SimGigeScanner>(sensor, plane, [this] {
      Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
      t.translation() = Eigen::Vector3d(0, sweep.load(), 200);
      return t;
    }, options);
  }
  void pulses(int n) {
    for (int k = 0; k < n; ++k) {
      device->set(true);
      device->set(false);
      sweep = sweep + 0.5;
    }
  }
  dr::GenicamConfig config() const {
    dr::GenicamConfig c;
    c.device = "127.0.0.1";
    return c;
  }
};

}  // namespace

TEST(GenicamScanner, ProfilesArriveInTriggerOrderAtTheRangeTheDeviceScaled) {
  Cell cell;
  dr::GenicamScanner scanner(cell.sensor, cell.config());
  // What the device stated (SFNC Scan3d features through the GenICam XML), not what we assumed.
  EXPECT_EQ(scanner.device().pixel_format, "Coord3D_C16");
  EXPECT_DOUBLE_EQ(scanner.device().scale_mm, 0.01);
  EXPECT_EQ(scanner.device().width, cell.sensor.samples_x + 2);
  EXPECT_EQ(scanner.device().height, 16);
  // 40 pulses: two full frames of 16 and a short one of 8, sent when no pulse follows.
  cell.pulses(40);
  const double sigma = cell.sensor.noise_cz_per_mm * 200.0 * 200.0;  // eq. 3.4 at normal incidence
  for (int k = 0; k < 40; ++k) {
    const dr::Profile p = scanner.acquire(2000ms);
    ASSERT_EQ(p.index, static_cast<std::uint64_t>(k));
    ASSERT_FALSE(p.lost);
    ASSERT_EQ(p.samples.size(), static_cast<std::size_t>(cell.sensor.samples_x));
    EXPECT_TRUE(p.truth.empty());  // a device on the wire has no simulation truth
    // Beside the wire, the simulated device kept it: the true hit of each ray on the plane z = 0, where the
    // camera stood at this pulse (y = 0.5 k), and it hands it over once.
    const std::vector<sp::SampleTruth> truth = cell.device->take_truth(p.index);
    ASSERT_EQ(truth.size(), p.samples.size());
    for (int i = 0; i < cell.sensor.samples_x; i += 100) {
      EXPECT_LT(truth[static_cast<std::size_t>(i)].triangle, 2u);
      EXPECT_NEAR(truth[static_cast<std::size_t>(i)].object_mm.z(), 0.0, 1e-3);
      EXPECT_NEAR(truth[static_cast<std::size_t>(i)].object_mm.y(), 0.5 * k, 1e-3);
      EXPECT_NEAR(truth[static_cast<std::size_t>(i)].object_mm.x(), p.samples[static_cast<std::size_t>(i)].camera_mm.x(), 0.05);
    }
    EXPECT_TRUE(cell.device->take_truth(p.index).empty());
    double sum = 0.0;
    int n = 0;
    for (int i = 0; i < cell.sensor.samples_x; ++i) {
      const auto& s = p.samples[static_cast<std::size_t>(i)];
      ASSERT_TRUE(s.valid()) << "profile " << k << " ray " << i;
      // On the plane z = -200 of the camera frame; x across the fan from the ray's angle.
      EXPECT_NEAR(s.camera_mm.z(), -200.0, 5.0 * sigma + 0.005);
      EXPECT_NEAR(s.camera_mm.x(), sp::ray_tan_x(cell.sensor, i) * -s.camera_mm.z(), 1e-3);
      EXPECT_NEAR(s.sigma_z_mm, sigma, 1e-3 * sigma);
      sum += s.camera_mm.z();
      ++n;
    }
    EXPECT_NEAR(sum / n, -200.0, 5.0 * sigma / std::sqrt(n) + 0.005);
  }
  EXPECT_EQ(scanner.counters().lost_profiles, 0u);
  EXPECT_EQ(scanner.counters().padding_lines, 8u);
  EXPECT_EQ(scanner.counters().frames, 3u);
}

TEST(GenicamScanner, ALostFrameIsReportedProfileByProfileWithoutShiftingTheRest) {
  Cell cell;
  dr::GenicamScanner scanner(cell.sensor, cell.config());
  cell.device->drop_next_frames(1);  // the first frame never reaches the host
  cell.pulses(32);
  for (int k = 0; k < 32; ++k) {
    const dr::Profile p = scanner.acquire(2000ms);
    ASSERT_EQ(p.index, static_cast<std::uint64_t>(k));
    EXPECT_EQ(p.lost, k < 16) << k;
    EXPECT_EQ(p.samples.empty(), k < 16) << k;
  }
  EXPECT_EQ(scanner.counters().lost_profiles, 16u);
}

TEST(GenicamScanner, NoPulseIsATimeoutThatNamesTheTriggerLine) {
  Cell cell;
  dr::GenicamScanner scanner(cell.sensor, cell.config());
  try {
    scanner.acquire(100ms);
    FAIL() << "no timeout";
  } catch (const dr::DriverError& e) {
    EXPECT_EQ(e.kind, dr::DriverError::Kind::timeout);
    EXPECT_THAT(e.what(), HasSubstr("no profile within 100 ms (is the trigger line Line0 wired and pulsing?)"));
  }
}

TEST(GenicamScanner, FeaturesAndSettingsOutOfRangeAreRefusedByName) {
  Cell cell;
  auto refused = [&](dr::GenicamConfig c, sp::SensorModel s, const std::string& text) {
    try {
      dr::GenicamScanner scanner(s, c);
      ADD_FAILURE() << "accepted; wanted: " << text;
    } catch (const dr::DriverError& e) {
      EXPECT_THAT(e.what(), HasSubstr(text));
    }
  };
  dr::GenicamConfig c = cell.config();
  c.trigger_line = "Line7";  // not a TriggerSource entry of the device
  refused(c, cell.sensor, "setting TriggerSource to Line7");
  c = cell.config();
  c.profiles_per_frame = 0;
  refused(c, cell.sensor, "scanner.profiles_per_frame: 0 outside [1, 2048]");
  c = cell.config();
  c.packet_size_bytes = 100;
  refused(c, cell.sensor, "scanner.packet_size_bytes: 100 outside [576, 9000]");
  sp::SensorModel wide = cell.sensor;
  wide.samples_x = 4000;  // more rays than the device's Width allows
  refused(cell.config(), wide, "setting Width to 4002");
  sp::SensorModel far = cell.sensor;
  far.range_max_mm = 1000.0;  // 65534 counts x 0.01 mm = 655 mm: the device cannot report R_max
  refused(cell.config(), far, "16-bit range reaches");
}

TEST(GenicamScanner, OpensTheDeviceByAddressSerialNumberOrUserId) {
  dr::SimGigeOptions o;
  o.serial = "SN48151623";
  o.user_id = "cell-a-scanner";
  Cell cell(o);
  for (const std::string id : {"127.0.0.1", "SN48151623", "cell-a-scanner"}) {
    dr::GenicamConfig c = cell.config();
    c.device = id;
    dr::GenicamScanner scanner(cell.sensor, c);
    EXPECT_EQ(scanner.device().vendor, "Aravis") << id;
    // A bare serial number resolves to the id Aravis knows the device by; the others are opened as given.
    EXPECT_EQ(scanner.device().id, id == "SN48151623" ? "Aravis-Fake-SN48151623" : id);
    // Each opening starts an acquisition, and the device's trigger counter with it.
    cell.pulses(3);
    for (int k = 0; k < 3; ++k) {
      const dr::Profile p = scanner.acquire(2000ms);
      EXPECT_EQ(p.index, static_cast<std::uint64_t>(k)) << id;
      EXPECT_FALSE(p.lost) << id;
    }
  }
  dr::GenicamConfig c = cell.config();
  c.device = "SN99999999";
  try {
    dr::GenicamScanner scanner(cell.sensor, c);
    FAIL() << "opened a device that is not there";
  } catch (const dr::DriverError& e) {
    EXPECT_EQ(e.kind, dr::DriverError::Kind::connection);
    EXPECT_THAT(e.what(), HasSubstr("opening 'SN99999999'"));
    EXPECT_THAT(e.what(), HasSubstr("check scanner.device"));
  }
}

// The scanner loses power mid-job: the driver says so (connection, not a silent stream of timeouts) once
// GigE Vision's heartbeat gives up on it, and a scanner that comes back is opened afresh and delivers.
TEST(GenicamScanner, ADeviceThatDisappearsIsAConnectionErrorAndOneThatReturnsOpensAgain) {
  Cell cell;
  {
    dr::GenicamScanner scanner(cell.sensor, cell.config());
    cell.device.reset();
    const auto t0 = std::chrono::steady_clock::now();
    dr::DriverError::Kind kind = dr::DriverError::Kind::timeout;
    std::string what;
    while (kind == dr::DriverError::Kind::timeout && std::chrono::steady_clock::now() - t0 < 20s) {
      try {
        scanner.acquire(500ms);
        FAIL() << "a profile from a device that is gone";
      } catch (const dr::DriverError& e) {
        kind = e.kind;
        what = e.what();
      }
    }
    EXPECT_EQ(kind, dr::DriverError::Kind::connection) << what;
    EXPECT_THAT(what, HasSubstr("stopped answering"));
  }
  cell.restart();
  dr::GenicamScanner scanner(cell.sensor, cell.config());
  cell.pulses(4);
  for (int k = 0; k < 4; ++k) {
    const dr::Profile p = scanner.acquire(2000ms);
    EXPECT_EQ(p.index, static_cast<std::uint64_t>(k));
    EXPECT_FALSE(p.lost);
  }
}

// A device without Coord3D_C16 (range data as plain Mono16): refused unless the scale is configured, then
// the same plane at 200 mm.
TEST(GenicamScanner, Mono16RangeDataNeedsAConfiguredScale) {
  dr::SimGigeOptions o;
  o.offer_coord3d = false;
  Cell cell(o);
  try {
    dr::GenicamScanner scanner(cell.sensor, cell.config());
    FAIL() << "Mono16 accepted without a scale";
  } catch (const dr::DriverError& e) {
    EXPECT_THAT(e.what(), HasSubstr("Mono16 range data needs scanner.mono16_scale_mm > 0"));
  }
  dr::GenicamConfig c = cell.config();
  c.mono16_scale_mm = 0.01;
  dr::GenicamScanner scanner(cell.sensor, c);
  EXPECT_EQ(scanner.device().pixel_format, "Mono16");
  cell.pulses(2);
  const double sigma = cell.sensor.noise_cz_per_mm * 200.0 * 200.0;
  for (int k = 0; k < 2; ++k) {
    const dr::Profile p = scanner.acquire(2000ms);
    double sum = 0.0;
    int n = 0;
    for (const auto& s : p.samples)
      if (s.valid()) sum += s.camera_mm.z(), ++n;
    EXPECT_EQ(n, cell.sensor.samples_x);
    EXPECT_NEAR(sum / n, -200.0, 5.0 * sigma / std::sqrt(n) + 0.005);
  }
}

// GevSCPSPacketSize: the smallest packet the standard allows splits each 16-line frame (8256 bytes) into 15
// packets; the device reads the size back and every profile still arrives, in order, none lost.
TEST(GenicamScanner, ThePacketSizeIsSetAndFramesArriveWhole) {
  Cell cell;
  dr::GenicamConfig c = cell.config();
  c.packet_size_bytes = 576;
  dr::GenicamScanner scanner(cell.sensor, c);
  EXPECT_EQ(scanner.device().packet_size_bytes, 576);
  cell.pulses(32);
  for (int k = 0; k < 32; ++k) {
    const dr::Profile p = scanner.acquire(2000ms);
    ASSERT_EQ(p.index, static_cast<std::uint64_t>(k));
    ASSERT_FALSE(p.lost) << k;
  }
  // No profile lost. (On a loaded CI host the stream also counted 20 incomplete buffers besides the 2 frames
  // that carried the profiles; they held none of them, so nothing was lost or shifted.)
  EXPECT_EQ(scanner.counters().lost_profiles, 0u);
}
