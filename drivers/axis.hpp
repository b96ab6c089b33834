#pragma once
// Axis drivers behind one small interface (PX4 style: hardware and simulation plug in at the same seam).
// Units at the interface: mm (linear) or rad (rotary); counts and scaling live in each driver's config.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace scancell::drivers {

/// Every hardware-layer failure, typed: which axis, which register or object, and why (Klipper style).
struct DriverError : std::runtime_error {
  enum class Kind { timeout, exception, connection, protocol, fault, refused, motion_timeout };
  Kind kind;
  std::string axis, where, cause;
  DriverError(Kind k, std::string axis_name, std::string where_, std::string cause_)
      : std::runtime_error(axis_name + ": " + where_ + ": " + cause_), kind(k), axis(std::move(axis_name)),
        where(std::move(where_)), cause(std::move(cause_)) {}
};
const char* to_string(DriverError::Kind k);

/// A move request every driver refuses the same way, before anything is sent: a non-finite target, or a
/// velocity that is not a finite non-negative number (0: the configured profile velocity).
void check_move_request(const std::string& axis, double target, double velocity);

/// `value` (mm, rad, or per second) in drive counts, refused (DriverError refused, naming the value and the
/// counts_per_unit setting) when it does not fit the drive's signed 32-bit register: 3,000,000 mm/s at 1000
/// counts/mm was sent as -1,294,967,296.
std::int32_t to_counts(const std::string& axis, const std::string& what, double value, double counts_per_unit);

struct AxisState {
  double position = 0.0;  // mm or rad
  double velocity = 0.0;  // per second
  bool enabled = false, homed = false, moving = false, in_position = false;
  bool faulted = false;
  std::uint16_t fault_code = 0;
};

class Axis {
 public:
  virtual ~Axis() = default;
  virtual const std::string& name() const = 0;
  virtual void enable() = 0;
  virtual void disable() = 0;
  virtual void home(std::chrono::milliseconds timeout) = 0;
  /// Commands the move and returns at once; `velocity` (per second) > 0 overrides the configured profile
  /// velocity for this move (the line-scan sweep runs at the scan speed).
  virtual void begin_move(double target, double velocity = 0.0) = 0;
  /// Waits for in-position after begin_move; DriverError(motion_timeout) and a halt when it does not come,
  /// DriverError(fault) when the axis stopped short of `target` (halted, e-stop).
  virtual void finish_move(double target, std::chrono::milliseconds timeout) = 0;
  void move_to(double target, std::chrono::milliseconds timeout) {
    begin_move(target);
    finish_move(target, timeout);
  }
  virtual void stop() = 0;  // controlled stop
  virtual void halt() = 0;  // quick stop
  virtual void reset_fault() = 0;
  virtual AxisState state() = 0;
  /// Position compare (scanner.trigger_source: drive_compare): the drive's compare output, wired to the
  /// scanner's trigger input, pulses once each time the axis reaches start + k·pitch (mm or rad),
  /// k = 0 … count−1, in the direction of pitch's sign; standing on the first position fires it. Drives
  /// without one refuse (DriverError refused, naming the setting to change).
  virtual void arm_position_compare(double start, double pitch, int count);
  /// Compare pulses fired since the last arm_position_compare.
  virtual int position_compare_fired();
};

struct SoftLimits {
  double min = 0.0, max = 0.0;
};

/// Named axes with soft limits checked before any command leaves the process.
class Positioner {
 public:
  void add(std::unique_ptr<Axis> axis, SoftLimits limits);
  Axis& axis(const std::string& name);
  /// Moves the named axes together, each to in-position; a target outside its limits refuses the whole move
  /// before anything is sent, naming the axis and the limit; an axis failing halts all of them.
  void move(const std::map<std::string, double>& targets, std::chrono::milliseconds timeout);
  /// Quick-stops every axis (e-stop path); errors of individual axes are collected, not thrown midway.
  std::vector<std::string> halt_all();
  /// Starts one axis' move at `velocity` (checked against the soft limits and the e-stop latch like move())
  /// and returns at once: the caller polls the axis (line-scan sweep with position-compare triggering) and
  /// ends with axis(name).finish_move().
  void begin_move(const std::string& name, double target, double velocity);
  std::vector<std::string> names() const;

  /// E-stop latch: halts every axis now; move() is refused until reset_estop().
  std::vector<std::string> latch_estop(const std::string& why);
  void reset_estop();
  bool estop_latched() const { return latched_; }

 private:
  void check_target(const std::string& name, double target) const;
  std::atomic<bool> latched_{false};
  std::string latch_reason_;
  struct Entry {
    std::unique_ptr<Axis> axis;
    SoftLimits limits;
  };
  std::map<std::string, Entry> axes_;
};

}  // namespace scancell::drivers
