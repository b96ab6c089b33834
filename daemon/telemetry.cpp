#include "daemon/telemetry.hpp"

#include <stdexcept>

namespace scancell::daemon {

std::int64_t Telemetry::now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

Telemetry::Telemetry(const std::string& url, double rate)
    : lcm_(url), axis_period_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / rate))) {
  if (!lcm_.good()) throw std::runtime_error("LCM: cannot start on " + url + " (is there a multicast route? see docs/telemetry.md)");
  if (!(rate > 0.0)) throw std::invalid_argument("telemetry: axis rate must be > 0");
}

void Telemetry::status(scancell::status_t m) {
  if (!m.utime) m.utime = now_us();
  lcm_.publish("SCANCELL_STATUS", &m);
}

bool Telemetry::axes(scancell::axis_state_t m) {
  const auto now = std::chrono::steady_clock::now();
  if (now - last_axes_ < axis_period_) return false;  // the bound on the axis-state rate
  last_axes_ = now;
  if (!m.utime) m.utime = now_us();
  m.n = static_cast<std::int32_t>(m.name.size());
  lcm_.publish("SCANCELL_AXIS_STATE", &m);
  return true;
}

void Telemetry::fault(scancell::fault_t m) {
  if (!m.utime) m.utime = now_us();
  lcm_.publish("SCANCELL_FAULT", &m);
}

void Telemetry::progress(std::int64_t job, const std::string& event) {
  scancell::progress_t m;
  m.utime = now_us();
  m.job_id = job;
  m.event = event;
  lcm_.publish("SCANCELL_PROGRESS", &m);
}

void Telemetry::plan(scancell::plan_t m) {
  if (!m.utime) m.utime = now_us();
  m.n = static_cast<std::int32_t>(m.scan_length_mm.size());
  lcm_.publish("SCANCELL_PLAN", &m);
}

}  // namespace scancell::daemon
