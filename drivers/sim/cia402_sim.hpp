#pragma once
// A simulated CANopen CiA 402 drive on one end of a frame stream (socketpair(AF_UNIX, SOCK_SEQPACKET) here,
// where the kernel has no CAN): NMT, expedited SDO with an object dictionary, heartbeat producer, the CiA 402
// state machine, profile position and homing with trapezoidal motion, and injectable faults. Every controlword
// write and set-point is logged; a set-point beyond the travel is counted as a violation.
#include <atomic>
#include <cstdint>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include <linux/can.h>

namespace scancell::drivers::sim {

// duplicate_reply_once: the next SDO reply is sent twice (a late reply after a retry looks the same to the client).
enum class CanFault { none, sdo_abort_once, missing_heartbeat, drive_fault, following_error, bus_off, duplicate_reply_once };

struct Cia402Params {
  double max_velocity_counts_s = 200000.0;
  double accel_counts_s2 = 2000000.0;
  std::int32_t min_counts = -1000000, max_counts = 1000000;
  double home_time_s = 0.05;
  double heartbeat_period_s = 0.05;
};

struct CanLogEntry {
  std::uint16_t index;
  std::uint32_t value;
};

class Cia402DriveSim {
 public:
  Cia402DriveSim(int fd, int node_id, Cia402Params params = {});  // takes ownership of fd
  ~Cia402DriveSim();
  Cia402DriveSim(const Cia402DriveSim&) = delete;
  Cia402DriveSim& operator=(const Cia402DriveSim&) = delete;
  void inject(CanFault f);
  std::vector<CanLogEntry> writes() const;  // SDO downloads received (controlword, target, ...)
  std::size_t limit_violations() const { return violations_; }
  std::int32_t actual_counts() const;

 private:
  void run();
  void step(double dt);
  void on_frame(const can_frame& frame);
  std::optional<std::uint32_t> upload(std::uint16_t index) const;  // SDO read; nothing: no such object
  void controlword(std::uint16_t value);                           // 0x6040 written: the state machine
  void reply_sdo(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t value);
  std::uint16_t statusword() const;

  int fd_;
  int node_;
  Cia402Params p_;
  std::atomic<bool> running_{true};
  std::atomic<CanFault> fault_{CanFault::none};
  std::thread thread_;
  mutable std::mutex mu_;
  enum class State { disabled, ready, switched_on, enabled, fault } state_ = State::disabled;
  std::int8_t mode_ = 0;
  std::uint16_t control_ = 0, error_code_ = 0;
  std::int32_t target_obj_ = 0, target_ = 0;
  std::uint32_t velocity_obj_ = 0;
  double pos_ = 0.0, vel_ = 0.0, homing_left_ = 0.0, heartbeat_left_ = 0.0;
  bool moving_ = false, ack_ = false, reached_ = true, following_ = false;
  std::vector<CanLogEntry> log_;
  std::size_t violations_ = 0;
};

}  // namespace scancell::drivers::sim
