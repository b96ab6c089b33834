#include "daemon/notify.hpp"

#include <cstdlib>

#include <systemd/sd-daemon.h>

namespace scancell::daemon {

ServiceNotifier::ServiceNotifier() {
  under_systemd_ = std::getenv("NOTIFY_SOCKET") != nullptr;
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0) watchdog_ = std::chrono::microseconds(usec);
}

bool ServiceNotifier::send(const std::string& state) {
  if (!under_systemd_) return false;
  return sd_notify(0, state.c_str()) > 0;
}

bool ServiceNotifier::ready(const std::string& s) { return send("READY=1\nSTATUS=" + s); }
bool ServiceNotifier::status(const std::string& s) { return send("STATUS=" + s); }
bool ServiceNotifier::watchdog() { return send("WATCHDOG=1"); }
bool ServiceNotifier::stopping(const std::string& s) { return send("STOPPING=1\nSTATUS=" + s); }

}  // namespace scancell::daemon
