// The CiA 402 axis driver against the simulated drive, frames over socketpair(AF_UNIX, SOCK_SEQPACKET) — the
// same struct can_frame read/write the SocketCAN path uses (this kernel has no CAN).
#include <chrono>
#include <functional>
#include <thread>

#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/socket.h>

#include "drivers/canopen_axis.hpp"
#include "drivers/sim/cia402_sim.hpp"

namespace dr = scancell::drivers;
namespace sim = scancell::drivers::sim;
using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {

struct Rig {
  std::unique_ptr<sim::Cia402DriveSim> drive;
  std::unique_ptr<dr::CanOpenAxis> axis;
  Rig() {
    int sv[2];
    if (::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) throw std::runtime_error("socketpair");
    drive = std::make_unique<sim::Cia402DriveSim>(sv[1], 5);
    dr::CanOpenConfig c;
    c.name = "turntable";
    c.node_id = 5;
    c.counts_per_unit = 10000.0;  // counts per rad
    c.profile_velocity = 5.0;
    axis = std::make_unique<dr::CanOpenAxis>(c, sv[0]);
  }
  std::size_t writes_of(std::uint16_t index) const {
    std::size_t n = 0;
    for (const auto& w : drive->writes()) n += w.index == index;
    return n;
  }
};

dr::DriverError error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const dr::DriverError& e) {
    return e;
  }
  ADD_FAILURE() << "no DriverError";
  return dr::DriverError(dr::DriverError::Kind::refused, "", "", "");
}

}  // namespace

TEST(CanOpen, EnableHomeMoveThroughTheCia402StateMachine) {
  Rig r;
  r.axis->enable();
  r.axis->home(2000ms);
  r.axis->move_to(1.5, 3000ms);
  const auto s = r.axis->state();
  EXPECT_TRUE(s.enabled);
  EXPECT_TRUE(s.homed);
  EXPECT_TRUE(s.in_position);
  EXPECT_DOUBLE_EQ(s.position, 1.5);
  EXPECT_EQ(r.drive->actual_counts(), 15000);
  // The handshake: shutdown, switch on, enable operation; then bit 4 up and down for homing and the move.
  std::vector<std::uint32_t> cw;
  for (const auto& w : r.drive->writes())
    if (w.index == 0x6040) cw.push_back(w.value);
  ASSERT_GE(cw.size(), 7u);
  EXPECT_EQ(cw[0], 0x06u);
  EXPECT_EQ(cw[1], 0x07u);
  EXPECT_EQ(cw[2], 0x0Fu);
  EXPECT_EQ(cw[3], 0x1Fu);
  EXPECT_EQ(r.drive->limit_violations(), 0u);
}

// Issue 16, defect 8: a second reply to the position read used to be taken as the answer to the next
// request, shifting every later read by one (a drive at 50 mm, enabled, read as 0 mm, disabled).
TEST(CanOpen, AStaleSdoReplyIsDroppedAndCountedNotTakenAsTheAnswer) {
  Rig r;
  r.axis->enable();
  r.axis->home(2000ms);
  r.axis->move_to(1.5, 3000ms);
  r.drive->inject(sim::CanFault::duplicate_reply_once);
  EXPECT_EQ(r.axis->sdo_read(0x6064, 0), 15000u);  // position, answered twice
  const std::uint32_t sw = r.axis->sdo_read(0x6041, 0);  // the duplicate arrives first and must be skipped
  EXPECT_NE(sw, 15000u);
  EXPECT_EQ(sw & 0x6Fu, 0x27u) << std::hex << sw;  // operation enabled
  EXPECT_EQ(r.axis->stale_sdo_replies(), 1u);
  const auto s = r.axis->state();
  EXPECT_TRUE(s.enabled);
  EXPECT_DOUBLE_EQ(s.position, 1.5);
}

TEST(CanOpen, SdoAbortIsDecodedAndNamesTheObject) {
  Rig r;
  r.axis->enable();
  r.drive->inject(sim::CanFault::sdo_abort_once);
  const auto e = error_of([&] { r.axis->sdo_write(0x6060, 0, 1, 1); });
  EXPECT_EQ(e.kind, dr::DriverError::Kind::exception);
  EXPECT_THAT(e.where, HasSubstr("0x6060:0"));
  EXPECT_THAT(e.cause, HasSubstr("present device state"));
  // An object the drive does not have: its own abort code, decoded.
  const auto none = error_of([&] { r.axis->sdo_read(0x2000, 0); });
  EXPECT_THAT(none.cause, HasSubstr("object does not exist"));
}

TEST(CanOpen, MissingHeartbeatFaultsTheAxisAndStopsMotionCommands) {
  Rig r;
  r.axis->enable();
  r.axis->home(2000ms);
  r.drive->inject(sim::CanFault::missing_heartbeat);
  std::this_thread::sleep_for(450ms);
  const auto e = error_of([&] { r.axis->move_to(2.0, 2000ms); });
  EXPECT_EQ(e.kind, dr::DriverError::Kind::fault);
  EXPECT_THAT(e.where, HasSubstr("heartbeat 0x705"));
  const std::size_t targets = r.writes_of(0x607A);
  EXPECT_EQ(error_of([&] { r.axis->move_to(2.0, 2000ms); }).kind, dr::DriverError::Kind::refused);
  EXPECT_EQ(r.writes_of(0x607A), targets);  // nothing more was commanded
}

TEST(CanOpen, DriveFaultAndFollowingErrorAreTypedWithTheirCodes) {
  Rig r;
  r.axis->enable();
  r.axis->home(2000ms);
  r.drive->inject(sim::CanFault::following_error);
  auto e = error_of([&] { r.axis->move_to(1.0, 2000ms); });
  EXPECT_EQ(e.kind, dr::DriverError::Kind::fault);
  EXPECT_THAT(e.cause, HasSubstr("0x8611"));
  EXPECT_THAT(e.cause, HasSubstr("following error"));
  r.axis->reset_fault();
  r.axis->enable();
  r.drive->inject(sim::CanFault::drive_fault);
  e = error_of([&] { r.axis->move_to(1.0, 2000ms); });
  EXPECT_EQ(e.kind, dr::DriverError::Kind::fault);
  EXPECT_THAT(e.cause, HasSubstr("0x2310"));
}

TEST(CanOpen, BusOffIsAConnectionError) {
  Rig r;
  r.axis->enable();
  r.drive->inject(sim::CanFault::bus_off);
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(error_of([&] { r.axis->state(); }).kind, dr::DriverError::Kind::connection);
}

TEST(CanOpen, SoftLimitsAreCheckedBeforeAnyFrameLeaves) {
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv), 0);
  sim::Cia402DriveSim drive(sv[1], 3);
  dr::CanOpenConfig c;
  c.name = "tilt";
  c.node_id = 3;
  c.counts_per_unit = 10000.0;
  dr::Positioner pos;
  pos.add(std::make_unique<dr::CanOpenAxis>(c, sv[0]), {-1.4, 1.4});
  pos.axis("tilt").enable();
  pos.axis("tilt").home(2000ms);
  const auto before = drive.writes().size();
  EXPECT_EQ(error_of([&] { pos.move({{"tilt", 2.0}}, 1000ms); }).kind, dr::DriverError::Kind::refused);
  EXPECT_EQ(drive.writes().size(), before);
  pos.move({{"tilt", 1.0}}, 3000ms);
  EXPECT_EQ(drive.actual_counts(), 10000);
  EXPECT_EQ(drive.limit_violations(), 0u);
}

TEST(CanOpen, ScancellSimServesADriveOnAUnixSocket) {
  // The demo path: scancell-sim can --unix PATH in another process, the driver opening "unix:PATH".
  const std::string path = "/tmp/scancell-can-test-" + std::to_string(::getpid());
  const std::string cmd = std::string("sleep 5 | ") + SCANCELL_SIM + " can --unix " + path + " --node 4 > /dev/null 2>&1 &";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  int fd = -1;
  for (int k = 0; k < 100 && fd < 0; ++k) {
    try {
      fd = dr::CanLink::open("unix:" + path);
    } catch (const dr::DriverError&) {
      std::this_thread::sleep_for(20ms);
    }
  }
  ASSERT_GE(fd, 0) << "scancell-sim did not come up";
  dr::CanOpenConfig c;
  c.name = "turntable";
  c.node_id = 4;
  c.counts_per_unit = 10000.0;
  dr::CanOpenAxis axis(c, fd);
  axis.enable();
  axis.home(2000ms);
  axis.move_to(0.5, 3000ms);
  EXPECT_DOUBLE_EQ(axis.state().position, 0.5);
}
