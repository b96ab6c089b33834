#pragma once
// scancell-sim's Modbus drive: a libmodbus server implementing docs/modbus-register-map.md with axis
// dynamics (trapezoidal moves, homing, limits) and injectable faults, on 127.0.0.1 TCP or on a
// pseudo-terminal (RTU over a real serial line discipline). Every command it receives is logged, and a target
// outside its travel is recorded as a violation (the tests assert there are none).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace scancell::drivers::sim {

enum class ModbusFault {
  none,
  no_reply,           // requests are read and dropped
  illegal_address,    // every request answered with exception 2
  busy_once,          // the next request answered with exception 6 (slave busy), then normal
  device_failure,     // every request answered with exception 4
  stall,              // moves start but never reach the target
  drop_connection,    // the connection is closed right after the next move command is answered
  following_error,    // the next move raises the drive's fault bit (following error)
  corrupt_once,       // RTU: the next reply goes out with a wrong CRC
  accept_and_close,   // TCP: the connection is dropped, and every new one is accepted and closed at once
  late_reply_once,    // the next reply is held 150 ms (past a 100 ms response timeout), then sent
};

struct DriveParams {
  double max_velocity_counts_s = 200000.0;
  double accel_counts_s2 = 2000000.0;
  std::int32_t min_counts = -1000000, max_counts = 1000000;
  double home_time_s = 0.05;
};

struct LoggedCommand {
  std::uint16_t command;
  std::int32_t target;
  std::chrono::steady_clock::time_point at;  // when the drive took it (latency checks, not the test's polling)
};

class ModbusDriveSim {
 public:
  explicit ModbusDriveSim(DriveParams params = {}, int unit_id = 1);
  ~ModbusDriveSim();
  ModbusDriveSim(const ModbusDriveSim&) = delete;
  ModbusDriveSim& operator=(const ModbusDriveSim&) = delete;

  /// Serves Modbus TCP on 127.0.0.1; returns the port (the first free one from `first_port`).
  int serve_tcp(int first_port = 15020);
  /// Serves Modbus RTU on a new pseudo-terminal; returns the path of its slave end for the client.
  std::string serve_rtu();
  void stop();

  void inject(ModbusFault f) { fault_ = f; }
  std::vector<LoggedCommand> commands() const;
  std::size_t limit_violations() const { return violations_; }
  int corrupt_replies_sent() const { return corrupt_sent_; }
  /// Writes refused as a drive would: to a read-only register, or a negative profile velocity.
  int refused_writes() const { return refused_writes_; }
  std::int32_t actual_counts() const;
  /// Position-compare pulses fired since the last arming (register 17).
  int compare_fired() const;

 private:
  void run_tcp(int listen_fd);
  void run_rtu(int master_fd);
  /// One request: returns false when the connection should be closed.
  bool handle(void* ctx, const std::uint8_t* req, int len);
  /// An injected fault that answers (or withholds) the reply itself: true when it did.
  bool answer_fault(void* ctx, const std::uint8_t* req, ModbusFault f);
  /// A command from the command register, executed (under mu_): false when the connection should be closed.
  bool execute(std::uint16_t cmd, std::int32_t target, ModbusFault f);
  /// The Modbus exception code a drive answers this write with, or 0 to accept it.
  unsigned refuse_write(void* ctx, const std::uint8_t* req, int len) const;
  void step(double dt);
  void fire_compare();  // under mu_

  DriveParams p_;
  int unit_;
  std::atomic<ModbusFault> fault_{ModbusFault::none};
  std::atomic<bool> running_{false};
  std::thread thread_;
  mutable std::mutex mu_;
  void* mapping_ = nullptr;   // modbus_mapping_t
  void* server_ctx_ = nullptr;
  int listen_fd_ = -1, pty_master_ = -1, pty_slave_ = -1;
  bool rtu_ = false;
  std::atomic<int> corrupt_sent_{0};
  std::atomic<int> refused_writes_{0};
  // drive state (counts)
  double pos_ = 0.0, vel_ = 0.0;
  std::int32_t target_ = 0;
  bool enabled_ = false, homed_ = false, moving_ = false, fault_bit_ = false, stalled_ = false;
  double homing_left_ = 0.0;
  std::uint16_t fault_code_ = 0, heartbeat_ = 0;
  double compare_start_ = 0.0, compare_pitch_ = 0.0;  // counts
  int compare_count_ = 0, compare_fired_ = 0;
  std::uint32_t compare_total_ = 0;
  std::vector<LoggedCommand> log_;
  std::size_t violations_ = 0;
};

}  // namespace scancell::drivers::sim
