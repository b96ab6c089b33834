// Trigger pulse trains and the interlock (e-stop latch) on simulated lines; the e-stop halts real Modbus
// drives (simulated peers over TCP) within one control cycle and refuses motion until reset; the simulated
// scanner takes one profile per trigger pulse.
#include <atomic>
#include <filesystem>
#include <fstream>
#include <variant>
#include <chrono>
#include <optional>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "drivers/config.hpp"
#include "drivers/gpio.hpp"
#include "drivers/modbus_axis.hpp"
#include "drivers/modbus_map.hpp"
#include "drivers/sim/sim_scanner.hpp"
#include "drivers/sim/modbus_sim.hpp"
#include "planner/config.hpp"

namespace dr = scancell::drivers;
namespace sim = scancell::drivers::sim;
using namespace std::chrono_literals;
using ::testing::HasSubstr;

TEST(Gpio, TriggerFiresTheArmedPulseTrain) {
  dr::SimOutput out;
  dr::Trigger trig(out);
  EXPECT_THROW(trig.fire(), dr::DriverError);  // not armed
  trig.arm(20, 200us, 1000us);
  trig.fire();
  trig.wait_done(1000ms);
  EXPECT_EQ(trig.pulses_fired(), 20);
  EXPECT_EQ(out.rising_edges(), 20u);
  const auto ch = out.changes();
  ASSERT_EQ(ch.size(), 40u);
  // 20 pulses at a 1 ms period take at least 19 ms from first rise to last rise.
  EXPECT_GE(ch[38].first - ch[0].first, 19ms);
  // And no two rises closer than the period, even when one was late (the schedule once caught up: under
  // ASan the train took 18.73 ms).
  for (std::size_t k = 2; k < ch.size(); k += 2) EXPECT_GE(ch[k].first - ch[k - 2].first, 1000us) << "rise " << k / 2;
  EXPECT_THROW(trig.arm(0, 200us, 1000us), dr::DriverError);
  EXPECT_THROW(trig.arm(5, 2000us, 1000us), dr::DriverError);
}

TEST(Gpio, GpiodLinesThatDoNotExistAreRefusedByName) {
  // This kernel has no GPIO chips: the libgpiod path must fail cleanly, naming chip and offset.
  try {
    dr::GpiodOutput out("gpiochip7", 3);
    GTEST_SKIP() << "a gpiochip7 exists here";
  } catch (const dr::DriverError& e) {
    EXPECT_EQ(e.kind, dr::DriverError::Kind::connection);
    EXPECT_THAT(e.where, HasSubstr("gpiochip7:3"));
  }
}

TEST(Interlock, EstopHaltsEveryAxisAtOnceAndLatchesUntilReset) {
  sim::ModbusDriveSim d1, d2;
  dr::ModbusConfig c1, c2;
  c1.name = "reach";
  c1.port = d1.serve_tcp(15100);
  c2.name = "lift";
  c2.port = d2.serve_tcp(c1.port + 1);
  for (auto* c : {&c1, &c2}) c->profile_velocity = 20.0;  // mm/s: a 30 mm move takes 1.5 s
  dr::Positioner pos;
  pos.add(std::make_unique<dr::ModbusAxis>(c1), {-500, 500});
  pos.add(std::make_unique<dr::ModbusAxis>(c2), {-500, 500});
  for (const char* n : {"reach", "lift"}) {
    pos.axis(n).enable();
    pos.axis(n).home(2000ms);
  }
  dr::SimInput estop(false);
  dr::Interlock interlock(estop, nullptr, pos);
  std::exception_ptr moving_error;
  std::thread mover([&] {
    try {
      pos.axis("reach").move_to(30.0, 5000ms);
    } catch (...) {
      moving_error = std::current_exception();
    }
  });
  std::this_thread::sleep_for(200ms);
  const auto pressed = std::chrono::steady_clock::now();
  estop.drive(true);
  // Both drives take a halt within one control cycle (the interlock waits 20 ms per edge poll; Modbus on
  // loopback adds about a millisecond): 50 ms from the press to each drive's own receipt is the bound
  // asserted. The drives time the halt themselves: a test thread that polls for it can be descheduled past
  // the bound on a loaded host while the halt itself was on time.
  auto halt_at = [](const sim::ModbusDriveSim& d) -> std::optional<std::chrono::steady_clock::time_point> {
    for (const auto& c : d.commands())
      if (c.command == dr::modbus_map::kHalt) return c.at;
    return std::nullopt;
  };
  while (std::chrono::steady_clock::now() - pressed < 2000ms && !(halt_at(d1) && halt_at(d2)))
    std::this_thread::sleep_for(1ms);
  for (const auto* d : {&d1, &d2}) {
    const auto at = halt_at(*d);
    ASSERT_TRUE(at) << "no halt within 2 s of the e-stop";
    EXPECT_LT(*at - pressed, 50ms) << "halt "
                                   << std::chrono::duration<double, std::milli>(*at - pressed).count() << " ms after the press";
  }
  mover.join();
  ASSERT_TRUE(moving_error);  // the interrupted move reports itself
  try {
    std::rethrow_exception(moving_error);
  } catch (const dr::DriverError& e) {
    EXPECT_THAT(e.cause, HasSubstr("interrupted"));
  }
  EXPECT_LT(d1.actual_counts(), 30000);
  // Latched: motion refused before anything is sent; reset refused while the e-stop is still pressed.
  const auto sent = d2.commands().size();
  EXPECT_THROW(pos.move({{"lift", 5.0}}, 2000ms), dr::DriverError);
  EXPECT_EQ(d2.commands().size(), sent);
  EXPECT_THROW(interlock.reset(), dr::DriverError);
  estop.drive(false);
  interlock.reset();
  pos.move({{"lift", 5.0}}, 3000ms);
  EXPECT_EQ(d2.actual_counts(), 5000);
  // Both axes move together: at some instant both drives are between their start and their target.
  pos.axis("reach").reset_fault();
  const std::int32_t r0 = d1.actual_counts(), l0 = d2.actual_counts();
  std::exception_ptr both_error;
  std::thread both([&] {
    try {
      pos.move({{"reach", 25.0}, {"lift", 25.0}}, 5000ms);
    } catch (...) {
      both_error = std::current_exception();
    }
  });
  bool together = false;
  for (int k = 0; k < 2000 && !together; ++k) {
    const std::int32_t r = d1.actual_counts(), l = d2.actual_counts();
    together = r > r0 && r < 25000 && l > l0 && l < 25000;
    std::this_thread::sleep_for(1ms);
  }
  both.join();
  EXPECT_FALSE(both_error);
  EXPECT_TRUE(together);
  EXPECT_EQ(d1.actual_counts(), 25000);
  EXPECT_EQ(d2.actual_counts(), 25000);
  EXPECT_THAT(interlock.events().front(), HasSubstr("e-stop active"));
}

namespace {

/// An axis whose halt takes until the test lets it finish: a drive answering slowly on its bus.
class SlowHaltAxis : public dr::Axis {
 public:
  const std::string& name() const override { return name_; }
  void enable() override {}
  void disable() override {}
  void home(std::chrono::milliseconds) override {}
  void begin_move(double, double) override {}
  void finish_move(double, std::chrono::milliseconds) override {}
  void stop() override {}
  void halt() override {
    halting = true;
    for (int k = 0; k < 2000 && !release; ++k) std::this_thread::sleep_for(1ms);
    halted = true;
  }
  void reset_fault() override {}
  dr::AxisState state() override { return {}; }
  std::atomic<bool> halting{false}, release{false}, halted{false};

 private:
  std::string name_ = "slow";
};

}  // namespace

TEST(Interlock, AResetWaitsForTheHaltsOfThePressItAnswers) {
  // The e-stop is pressed and released while the axis is still taking its halt; a reset then must not clear
  // the latch before the halt is done, nor be journalled before the press (it once was, under load in CI).
  dr::Positioner pos;
  auto slow = std::make_unique<SlowHaltAxis>();
  SlowHaltAxis& axis = *slow;
  pos.add(std::move(slow), {-500, 500});
  dr::SimInput estop(false);
  dr::Interlock interlock(estop, nullptr, pos);
  estop.drive(true);
  for (int k = 0; k < 2000 && !axis.halting; ++k) std::this_thread::sleep_for(1ms);
  ASSERT_TRUE(axis.halting) << "no halt within 2 s of the e-stop";
  estop.drive(false);
  std::atomic<bool> reset_done{false};
  std::thread resetter([&] {
    interlock.reset();
    reset_done = true;
  });
  std::this_thread::sleep_for(100ms);
  EXPECT_FALSE(reset_done) << "the reset returned while the halt was still going out";
  EXPECT_TRUE(interlock.latched());
  axis.release = true;
  resetter.join();
  EXPECT_TRUE(axis.halted);
  EXPECT_FALSE(interlock.latched());
  const auto events = interlock.events();
  ASSERT_EQ(events.size(), 2u);
  EXPECT_THAT(events[0], HasSubstr("e-stop active"));
  EXPECT_EQ(events[1], "reset");
}

TEST(SimScanner, OneProfilePerTriggerPulseAtTheAxesPose) {
  // A plane at z = 0; the camera 200 mm above looking down, swept 0.5 mm along its y per pulse (the sweep
  // axis): every pulse gives a profile of N_x samples on the plane, at the sweep position of that pulse.
  namespace sp = scancell::planner;
  const sp::SensorModel sensor = sp::load_sensor(std::string(SCANCELL_SOURCE_DIR) + "/config/sensors/line-scan-thesis.yaml");
  sp::TriangleMesh plane;
  plane.vertices = {{-300, -300, 0}, {300, -300, 0}, {300, 300, 0}, {-300, 300, 0}};
  plane.triangles = {{0, 1, 2}, {0, 2, 3}};
  std::atomic<double> sweep{0.0};
  auto pose = [&] {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();  // camera z up: boresight down, y along world Y
    t.translation() = Eigen::Vector3d(0, sweep.load(), 200);
    return t;
  };
  dr::SimScanner scanner(sensor, plane, pose);
  // The trigger drives the scanner's input; the sweep advances between pulses.
  std::thread sweeper([&] {
    for (int k = 0; k < 10; ++k) {
      scanner.set(true);
      scanner.set(false);
      sweep = sweep + 0.5;
    }
  });
  sweeper.join();
  for (int k = 0; k < 10; ++k) {
    const dr::Profile p = scanner.acquire(1000ms);
    EXPECT_EQ(p.index, static_cast<std::uint64_t>(k));
    ASSERT_EQ(p.samples.size(), static_cast<std::size_t>(sensor.samples_x));
    ASSERT_EQ(p.truth.size(), p.samples.size());
    std::size_t valid = 0;
    for (std::size_t c = 0; c < p.samples.size(); ++c) {
      if (!p.samples[c].valid()) continue;
      ++valid;
      EXPECT_NEAR(p.truth[c].object_mm.z(), 0.0, 1e-3);
      EXPECT_NEAR(p.truth[c].object_mm.y(), 0.5 * k, 1e-3);
    }
    EXPECT_EQ(valid, static_cast<std::size_t>(sensor.samples_x));
  }
  EXPECT_THROW(scanner.acquire(20ms), dr::DriverError);
}
