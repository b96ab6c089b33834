#pragma once
// Digital I/O for the scanner trigger and the interlocks, behind two small interfaces: a libgpiod (v1.6)
// implementation by chip name and line offset (consumer "scancell"), and a simulated one for tests and the
// demo (this kernel has no GPIO chips).
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "drivers/axis.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace scancell::drivers {

class DigitalOutput {
 public:
  virtual ~DigitalOutput() = default;
  virtual void set(bool level) = 0;
};

class DigitalInput {
 public:
  virtual ~DigitalInput() = default;
  virtual bool get() = 0;
  /// The next edge within the timeout: the new level; nullopt on timeout.
  virtual std::optional<bool> wait_edge(std::chrono::milliseconds timeout) = 0;
};

/// libgpiod v1.6 lines. Throws DriverError(connection) naming the chip and offset when a line cannot be had.
class GpiodOutput : public DigitalOutput {
 public:
  GpiodOutput(const std::string& chip, unsigned offset, bool initial = false);
  ~GpiodOutput() override;
  void set(bool level) override;

 private:
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  std::string where_;
};

class GpiodInput : public DigitalInput {
 public:
  GpiodInput(const std::string& chip, unsigned offset);
  ~GpiodInput() override;
  bool get() override;
  std::optional<bool> wait_edge(std::chrono::milliseconds timeout) override;

 private:
  gpiod_chip* chip_ = nullptr;
  gpiod_line* line_ = nullptr;
  std::string where_;
};

/// Simulated lines: an output records every level change with its time; an input is driven by the test.
class SimOutput : public DigitalOutput {
 public:
  void set(bool level) override;
  std::vector<std::pair<std::chrono::steady_clock::time_point, bool>> changes() const;
  std::size_t rising_edges() const;

 private:
  mutable std::mutex mu_;
  std::vector<std::pair<std::chrono::steady_clock::time_point, bool>> changes_;
};

class SimInput : public DigitalInput {
 public:
  explicit SimInput(bool level = false) : level_(level) {}
  void drive(bool level);  // the test (or the simulated cell) changes the input
  bool get() override;
  std::optional<bool> wait_edge(std::chrono::milliseconds timeout) override;

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool level_;
  std::deque<bool> edges_;
};

/// Scanner trigger: a pulse train of `count` pulses of `width` every `period` on one output.
class Trigger {
 public:
  explicit Trigger(DigitalOutput& out) : out_(out) {}
  ~Trigger();
  void arm(int count, std::chrono::microseconds width, std::chrono::microseconds period);
  void fire();  // starts the armed train (refused when not armed or already running)
  /// Waits for the train to finish; DriverError(timeout) when it does not.
  void wait_done(std::chrono::milliseconds timeout);
  int pulses_fired() const { return fired_; }
  void abort();

 private:
  DigitalOutput& out_;
  int count_ = 0;
  std::chrono::microseconds width_{0}, period_{0};
  bool armed_ = false;
  std::atomic<int> fired_{0};
  std::atomic<bool> stop_{false}, running_{false};
  std::thread thread_;
};

/// E-stop and door inputs watched on a thread. An active e-stop edge latches: every axis of the positioner is
/// halted at once and motion is refused until reset() (which requires the e-stop released). Door opening
/// halts too (and latches) when `door_halts`.
class Interlock {
 public:
  Interlock(DigitalInput& estop, DigitalInput* door, Positioner& positioner, bool estop_active_high = true,
            bool door_halts = true);
  ~Interlock();
  bool latched() const { return positioner_.estop_latched(); }
  void reset();
  std::vector<std::string> events() const;  // what happened, in order, for the journal

 private:
  void watch(DigitalInput& in, const std::string& name, bool active_level);
  DigitalInput& estop_;
  DigitalInput* door_;
  Positioner& positioner_;
  bool estop_high_;
  std::atomic<bool> running_{true};
  std::vector<std::thread> threads_;
  std::mutex latching_;  // held from a latch's halt to its record, and by reset(): a reset never interleaves with one
  mutable std::mutex mu_;
  std::vector<std::string> events_;
};

}  // namespace scancell::drivers
