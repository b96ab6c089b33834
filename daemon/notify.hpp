#pragma once
// systemd service notifications (libsystemd sd_notify): READY, STATUS, WATCHDOG, STOPPING. Without a
// NOTIFY_SOCKET (not run by systemd) every call is a no-op that says so; errors never stop the daemon.
#include <chrono>
#include <string>

namespace scancell::daemon {

class ServiceNotifier {
 public:
  ServiceNotifier();
  bool under_systemd() const { return under_systemd_; }
  /// The watchdog period systemd expects pings within (WatchdogSec), zero when none is configured.
  std::chrono::microseconds watchdog_period() const { return watchdog_; }
  bool ready(const std::string& status);
  bool status(const std::string& status);
  bool watchdog();
  bool stopping(const std::string& status);

 private:
  bool send(const std::string& state);
  bool under_systemd_ = false;
  std::chrono::microseconds watchdog_{0};
};

}  // namespace scancell::daemon
