#pragma once
// A CANopen CiA 402 drive as an Axis: NMT, expedited SDO (abort codes decoded), heartbeat consumer, the CiA 402
// state machine (controlword 0x6040 / statusword 0x6041), profile position mode (0x6060 = 1, target 0x607A,
// profile velocity 0x6081, new set-point handshake, target reached), homing mode (6), position actual 0x6064.
//
// Frames are struct can_frame read and written on a file descriptor: a SocketCAN raw socket in production
// (CanLink::open_socketcan), one end of socketpair(AF_UNIX, SOCK_SEQPACKET) in tests (this kernel has no CAN).
// The driver code is the same for both.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

#include <linux/can.h>

#include "drivers/axis.hpp"

namespace scancell::drivers {

/// A CAN frame stream on a file descriptor (owned).
class CanLink {
 public:
  explicit CanLink(int fd) : fd_(fd) {}
  ~CanLink();
  CanLink(const CanLink&) = delete;
  CanLink& operator=(const CanLink&) = delete;
  /// Raw SocketCAN socket bound to an interface (can0 ...): the production path.
  static int open_socketcan(const std::string& interface);
  /// A SOCK_SEQPACKET Unix socket carrying struct can_frame records (scancell-sim's simulated bus, for the
  /// demo where the kernel has no CAN).
  static int open_unix(const std::string& path);
  /// "unix:PATH" opens open_unix(PATH), anything else open_socketcan(name).
  static int open(const std::string& interface);
  void send(const can_frame& f);
  /// Next frame within the timeout; false on timeout. Throws DriverError(connection) when the link is gone.
  bool receive(can_frame& f, std::chrono::milliseconds timeout);
  int fd() const { return fd_; }

 private:
  int fd_;
};

/// An expedited SDO frame (CiA 301): command byte, index (little endian), sub-index, 32-bit value (little
/// endian). The driver's requests (0x600 + node) and the simulated drive's replies (0x580 + node) share it.
can_frame sdo_frame(std::uint32_t cob_id, std::uint8_t command, std::uint16_t index, std::uint8_t sub, std::uint32_t value);
/// The 32-bit value (or abort code) of an SDO frame.
std::uint32_t sdo_value(const can_frame& f);

/// SDO abort code (CiA 301) in words.
std::string sdo_abort_text(std::uint32_t code);

struct CanOpenConfig {
  std::string name;
  int node_id = 1;
  double counts_per_unit = 1000.0;
  double profile_velocity = 50.0;                    // mm/s or rad/s
  std::chrono::milliseconds sdo_timeout{100};
  int sdo_retries = 1;
  std::chrono::milliseconds heartbeat_timeout{300};  // consumer time: a silent drive faults the axis
  std::chrono::milliseconds poll_period{5};
};

class CanOpenAxis : public Axis {
 public:
  CanOpenAxis(CanOpenConfig config, int fd);  // takes ownership of fd
  const std::string& name() const override { return cfg_.name; }
  void enable() override;
  void disable() override;
  void home(std::chrono::milliseconds timeout) override;
  void begin_move(double target, double velocity = 0.0) override;
  void finish_move(double target, std::chrono::milliseconds timeout) override;
  void stop() override;
  void halt() override;
  void reset_fault() override;
  AxisState state() override;
  bool faulted() const { return faulted_; }

  // SDO client, public for diagnostics and tests.
  void sdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value, int bytes);
  std::uint32_t sdo_read(std::uint16_t index, std::uint8_t sub);
  /// SDO replies dropped because they answered another object than the request (late or duplicated).
  std::uint64_t stale_sdo_replies() const { return stale_sdo_replies_; }

 private:
  [[noreturn]] void fail(DriverError::Kind kind, const std::string& where, const std::string& cause);
  void refuse_if_faulted(const std::string& what) const;
  void nmt(std::uint8_t command);
  /// One SDO request/response (retries, heartbeat check, aborts decoded); the reply frame.
  can_frame sdo_transfer(std::uint8_t command, std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                         const std::string& where);
  void absorb(const can_frame& f);  // heartbeat and other unsolicited frames
  void check_heartbeat(const std::string& what);
  std::uint16_t statusword();
  void wait_status(std::uint16_t mask, std::uint16_t value, std::chrono::milliseconds timeout, const std::string& what);

  CanOpenConfig cfg_;
  std::mutex io_;
  CanLink link_;
  bool faulted_ = false;
  bool homed_ = false;  // CiA 402 has no homed bit outside homing mode: the driver remembers a completed homing
  std::chrono::steady_clock::time_point last_heartbeat_;
  bool heartbeat_seen_ = false;
  std::atomic<std::uint64_t> stale_sdo_replies_{0};
};

}  // namespace scancell::drivers
