#include "drivers/gpio.hpp"

#include <cerrno>
#include <cstring>

#include <gpiod.h>

namespace scancell::drivers {
namespace {

constexpr const char* kConsumer = "scancell";

std::pair<gpiod_chip*, gpiod_line*> open_line(const std::string& chip, unsigned offset, const std::string& where) {
  gpiod_chip* c = gpiod_chip_open_lookup(chip.c_str());
  if (!c) throw DriverError(DriverError::Kind::connection, "gpio", where, std::string("cannot open chip: ") + std::strerror(errno));
  gpiod_line* l = gpiod_chip_get_line(c, offset);
  if (!l) {
    gpiod_chip_close(c);
    throw DriverError(DriverError::Kind::connection, "gpio", where, std::string("no such line: ") + std::strerror(errno));
  }
  return {c, l};
}

}  // namespace

GpiodOutput::GpiodOutput(const std::string& chip, unsigned offset, bool initial)
    : where_(chip + ":" + std::to_string(offset)) {
  std::tie(chip_, line_) = open_line(chip, offset, where_);
  if (gpiod_line_request_output(line_, kConsumer, initial ? 1 : 0) != 0) {
    gpiod_chip_close(chip_);
    throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("request output: ") + std::strerror(errno));
  }
}

GpiodOutput::~GpiodOutput() {
  if (line_) gpiod_line_release(line_);
  if (chip_) gpiod_chip_close(chip_);
}

void GpiodOutput::set(bool level) {
  if (gpiod_line_set_value(line_, level ? 1 : 0) != 0)
    throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("set: ") + std::strerror(errno));
}

GpiodInput::GpiodInput(const std::string& chip, unsigned offset) : where_(chip + ":" + std::to_string(offset)) {
  std::tie(chip_, line_) = open_line(chip, offset, where_);
  if (gpiod_line_request_both_edges_events(line_, kConsumer) != 0) {
    gpiod_chip_close(chip_);
    throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("request events: ") + std::strerror(errno));
  }
}

GpiodInput::~GpiodInput() {
  if (line_) gpiod_line_release(line_);
  if (chip_) gpiod_chip_close(chip_);
}

bool GpiodInput::get() {
  const int v = gpiod_line_get_value(line_);
  if (v < 0) throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("get: ") + std::strerror(errno));
  return v != 0;
}

std::optional<bool> GpiodInput::wait_edge(std::chrono::milliseconds timeout) {
  timespec ts{static_cast<time_t>(timeout.count() / 1000), static_cast<long>((timeout.count() % 1000) * 1000000)};
  const int r = gpiod_line_event_wait(line_, &ts);
  if (r < 0) throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("wait: ") + std::strerror(errno));
  if (r == 0) return std::nullopt;
  gpiod_line_event ev{};
  if (gpiod_line_event_read(line_, &ev) != 0)
    throw DriverError(DriverError::Kind::connection, "gpio", where_, std::string("read event: ") + std::strerror(errno));
  return ev.event_type == GPIOD_LINE_EVENT_RISING_EDGE;
}

// ---- simulated lines ----

void SimOutput::set(bool level) {
  std::lock_guard<std::mutex> lock(mu_);
  changes_.emplace_back(std::chrono::steady_clock::now(), level);
}

std::vector<std::pair<std::chrono::steady_clock::time_point, bool>> SimOutput::changes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return changes_;
}

std::size_t SimOutput::rising_edges() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::size_t n = 0;
  bool last = false;
  for (const auto& [t, v] : changes_) {
    n += v && !last;
    last = v;
  }
  return n;
}

void SimInput::drive(bool level) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (level == level_) return;
    level_ = level;
    edges_.push_back(level);
  }
  cv_.notify_all();
}

bool SimInput::get() {
  std::lock_guard<std::mutex> lock(mu_);
  return level_;
}

std::optional<bool> SimInput::wait_edge(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!cv_.wait_for(lock, timeout, [&] { return !edges_.empty(); })) return std::nullopt;
  const bool v = edges_.front();
  edges_.pop_front();
  return v;
}

// ---- trigger ----

Trigger::~Trigger() { abort(); }

void Trigger::arm(int count, std::chrono::microseconds width, std::chrono::microseconds period) {
  if (running_) throw DriverError(DriverError::Kind::refused, "trigger", "arm", "a pulse train is running");
  if (count < 1 || width.count() <= 0 || period <= width)
    throw DriverError(DriverError::Kind::refused, "trigger", "arm", "need count >= 1 and 0 < width < period");
  count_ = count;
  width_ = width;
  period_ = period;
  armed_ = true;
  fired_ = 0;
}

void Trigger::fire() {
  if (!armed_ || running_) throw DriverError(DriverError::Kind::refused, "trigger", "fire", armed_ ? "already running" : "not armed");
  if (thread_.joinable()) thread_.join();
  armed_ = false;
  stop_ = false;
  running_ = true;
  thread_ = std::thread([this] {
    auto next = std::chrono::steady_clock::now();
    for (int k = 0; k < count_ && !stop_; ++k) {
      std::this_thread::sleep_until(next);
      out_.set(true);
      // The next rise is a period after this one really happened: after a late pulse the train runs late
      // rather than catching up with two pulses closer than the scanner's frame period.
      next = std::chrono::steady_clock::now() + period_;
      std::this_thread::sleep_for(width_);
      out_.set(false);
      ++fired_;
    }
    running_ = false;
  });
}

void Trigger::wait_done(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (running_ && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (running_) throw DriverError(DriverError::Kind::timeout, "trigger", "wait", std::to_string(fired_) + " of " + std::to_string(count_) + " pulses fired");
  if (thread_.joinable()) thread_.join();
}

void Trigger::abort() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  running_ = false;
}

// ---- interlock ----

Interlock::Interlock(DigitalInput& estop, DigitalInput* door, Positioner& positioner, bool estop_active_high, bool door_halts)
    : estop_(estop), door_(door), positioner_(positioner), estop_high_(estop_active_high) {
  threads_.emplace_back([this] { watch(estop_, "e-stop", estop_high_); });
  if (door_ && door_halts) threads_.emplace_back([this] { watch(*door_, "door", true); });
}

Interlock::~Interlock() {
  running_ = false;
  for (auto& t : threads_) t.join();
}

void Interlock::watch(DigitalInput& in, const std::string& name, bool active_level) {
  while (running_) {
    const auto edge = in.wait_edge(std::chrono::milliseconds(20));
    if (!edge || *edge != active_level) continue;
    // Halt first, record after: the halt is what must not wait (only a reset in progress, which sets a flag,
    // holds `latching_`). A reset waits for the halts and their record: without that it could clear the latch
    // while halt_all still went over the bus and be journalled before the press it answers (CI, under load).
    std::lock_guard<std::mutex> latch(latching_);
    const auto errors = positioner_.latch_estop(name);
    std::lock_guard<std::mutex> lock(mu_);
    events_.push_back(name + " active: all axes halted, motion latched off");
    for (const auto& e : errors) events_.push_back("halt failed: " + e);
  }
}

void Interlock::reset() {
  std::lock_guard<std::mutex> latch(latching_);
  if (estop_.get() == estop_high_)
    throw DriverError(DriverError::Kind::refused, "interlock", "reset", "e-stop still active");
  positioner_.reset_estop();
  std::lock_guard<std::mutex> lock(mu_);
  events_.push_back("reset");
}

std::vector<std::string> Interlock::events() const {
  std::lock_guard<std::mutex> lock(mu_);
  return events_;
}

}  // namespace scancell::drivers
