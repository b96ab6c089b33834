#pragma once
// LCM telemetry of the daemon (lcmtypes/*.lcm): status, plan, axis state (rate-limited), progress events and
// faults on channels prefixed SCANCELL_. Watch with lcm-spy, record with lcm-logger (docs/telemetry.md).
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "scancell/axis_state_t.hpp"
#include "scancell/fault_t.hpp"
#include "scancell/plan_t.hpp"
#include "scancell/progress_t.hpp"
#include "scancell/status_t.hpp"

namespace scancell::daemon {

/// Default: UDP multicast on the loopback route, never leaving the host (ttl=0).
inline constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

class Telemetry {
 public:
  /// Throws std::runtime_error naming the URL when LCM cannot start (e.g. no multicast route).
  explicit Telemetry(const std::string& url = kDefaultLcmUrl, double axis_rate_hz = 20.0);
  void status(scancell::status_t msg);
  /// Published at most axis_rate_hz times a second; returns whether this one went out.
  bool axes(scancell::axis_state_t msg);
  void fault(scancell::fault_t msg);
  void progress(std::int64_t job, const std::string& event);
  void plan(scancell::plan_t msg);

  static std::int64_t now_us();

 private:
  lcm::LCM lcm_;
  std::chrono::steady_clock::duration axis_period_;
  std::chrono::steady_clock::time_point last_axes_{};
};

}  // namespace scancell::daemon
