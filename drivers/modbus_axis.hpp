#pragma once
// An axis on a Modbus drive (libmodbus, TCP or RTU) speaking the register map of docs/modbus-register-map.md.
// Transient errors (timeout, slave busy, bad CRC) retry within the budget, then the axis faults; a lost
// connection reconnects with backoff and the axis re-reads the drive's state before anything else — a move is
// never re-sent blindly. A reply out of step with its request (a late reply to an earlier one) resynchronises
// the link (TCP: a fresh connection; RTU: the line drained) instead of shifting every later reply by one.
#include <atomic>
#include <chrono>
#include <mutex>
#include <string>

#include "drivers/axis.hpp"

struct _modbus;  // libmodbus context (modbus_t)

namespace scancell::drivers {

struct ModbusConfig {
  std::string name;                        // the axis name in messages and in the cell
  enum class Transport { tcp, rtu } transport = Transport::tcp;
  std::string host = "127.0.0.1";
  int port = 1502;
  std::string device;                      // RTU serial device (/dev/ttyUSB0, a pty in tests)
  int baud = 115200;
  char parity = 'N';
  int unit_id = 1;
  double counts_per_unit = 1000.0;         // drive counts per mm (linear) or per rad (rotary)
  double profile_velocity = 50.0;          // mm/s or rad/s for moves
  std::chrono::milliseconds response_timeout{150};
  int retries = 2;                         // extra attempts for transient errors
  std::chrono::milliseconds reconnect_backoff{50};  // doubled per attempt
  /// Reconnects in a row without one successful transaction between them: a peer that accepts and closes at
  /// once "reconnects" every time, so a working link, not a connect, resets the count.
  int reconnect_attempts = 3;
  std::chrono::milliseconds poll_period{5};
};

class ModbusAxis : public Axis {
 public:
  explicit ModbusAxis(ModbusConfig config);
  ~ModbusAxis() override;
  ModbusAxis(const ModbusAxis&) = delete;
  ModbusAxis& operator=(const ModbusAxis&) = delete;

  const std::string& name() const override { return cfg_.name; }
  void enable() override;
  void disable() override;
  void home(std::chrono::milliseconds timeout) override;
  void begin_move(double target, double velocity = 0.0) override;
  void finish_move(double target, std::chrono::milliseconds timeout) override;
  void stop() override;
  /// Reaches the drive within a bounded time even while another thread's transaction is stuck retrying or
  /// reconnecting: that transaction gives way (fails "gave way to a halt") and the halt goes out next.
  void halt() override;
  void reset_fault() override;
  AxisState state() override;
  /// Registers 12-16 and command 8 (docs/modbus-register-map.md); the pitch goes out in 1/1000 counts.
  void arm_position_compare(double start, double pitch, int count) override;
  int position_compare_fired() override;
  /// What the compare is armed with and has fired (registers 12-19 in one read; start and pitch in mm or
  /// rad): a simulated scanner on the compare output's wire reads it to know where each pulse came.
  struct CompareState {
    double start = 0.0, pitch = 0.0;
    int count = 0, fired = 0;
    std::uint32_t total = 0;  // pulses since the drive's power-up
  };
  CompareState position_compare();
  /// The driver gave up on the drive (retries exhausted or a drive fault): only reset_fault() is accepted.
  bool faulted() const { return faulted_; }

 private:
  void connect();
  void close_link();  // closes and frees the context (none afterwards)
  void reconnect(const std::string& where);
  void resync(const std::string& where);
  void pause(std::chrono::milliseconds d);
  void give_way_to_halt(const std::string& where);
  void read(int addr, int n, std::uint16_t* out, const std::string& what);
  void write(int addr, int n, const std::uint16_t* values, const std::string& what);
  void command(std::uint16_t cmd, const std::string& what);
  void wait_for(std::uint16_t bits, std::chrono::milliseconds timeout, const std::string& what);
  [[noreturn]] void fail(DriverError::Kind kind, const std::string& where, const std::string& cause);
  void refuse_if_faulted(const std::string& what) const;

  ModbusConfig cfg_;
  std::recursive_timed_mutex io_;  // serialises transactions (reconnect nests inside read/write)
  _modbus* ctx_ = nullptr;
  std::atomic<bool> faulted_{false};
  std::atomic<bool> halt_waiting_{false};  // a halt waits for io_: retries and reconnects stop
  int reconnects_in_row_ = 0;              // under io_; reset by a successful transaction
};

}  // namespace scancell::drivers
