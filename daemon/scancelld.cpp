// scancelld: the scanning cell's daemon, in the foreground (systemd Type=notify; docs/daemon.md).
//   scancelld --config FILE [--data-dir DIR] [--socket PATH]
//   scancelld --check DATA_DIR    the journal's consistency, as one JSON object (exit 0 consistent, 5 not)
// Exit codes: 0 stopped by SIGTERM/SIGINT, 2 usage, 4 configuration refused, 5 journal inconsistent, 1 anything
// else at start.
#include <csignal>
#include <cstring>
#include <cstdio>
#include <iostream>
#include <map>
#include <string>

#include <signal.h>
#include <sys/stat.h>

#include "daemon/daemon.hpp"
#include "common/errors.hpp"

namespace {

/// Every referenced scan file intact, every stored view with its scan, and no view scanned twice: the
/// "view K/N stored" events of a round must each appear at most once.
int check_journal(const std::string& dir) {
  using nlohmann::json;
  scancell::daemon::Journal journal(dir, scancell::daemon::Journal::Open::inspect);
  json out = {{"problems", journal.check()}, {"jobs", json::array()}};
  for (const auto& j : journal.jobs(1000000)) {
    std::size_t scans = 0;
    for (auto p : journal.plans(j.id)) scans += journal.scans(p).size();
    std::map<std::pair<int, int>, int> stored;
    int round = 0, repeats = 0;
    for (const auto& e : journal.events(j.id)) {
      if (e.rfind("executing: round ", 0) == 0) round = std::atoi(e.c_str() + 17);
      int k = 0, n = 0;
      if (std::sscanf(e.c_str(), "view %d/%d stored", &k, &n) == 2 && ++stored[{round, k}] > 1) ++repeats;
    }
    if (repeats) out["problems"].push_back("job " + std::to_string(j.id) + ": " + std::to_string(repeats) + " views scanned twice");
    if (stored.size() > scans)
      out["problems"].push_back("job " + std::to_string(j.id) + ": " + std::to_string(stored.size()) + " views reported stored, " + std::to_string(scans) + " scans in the journal");
    out["jobs"].push_back({{"job", j.id}, {"state", scancell::daemon::to_string(j.state)}, {"scans", scans}, {"repeats", repeats}});
  }
  out["ok"] = out["problems"].empty();
  std::cout << out.dump() << std::endl;
  return out["ok"].get<bool>() ? 0 : 5;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--check") {
    try {
      return check_journal(argv[2]);
    } catch (const std::exception& e) {
      std::cerr << "scancelld: --check: " << e.what() << "\n";
      return 5;
    }
  }
  std::string config, data_dir, socket;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--config" && i + 1 < argc) config = argv[++i];
    else if (a == "--data-dir" && i + 1 < argc) data_dir = argv[++i];
    else if (a == "--socket" && i + 1 < argc) socket = argv[++i];
    else {
      std::cerr << "usage: scancelld --config FILE [--data-dir DIR] [--socket PATH]\n";
      return 2;
    }
  }
  if (config.empty()) {
    std::cerr << "usage: scancelld --config FILE [--data-dir DIR] [--socket PATH]\n";
    return 2;
  }
  // Signals go to the main thread's sigtimedwait only: block them before any thread exists.
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  // The journal, its WAL, scans and reports are the cell's data: owner and group only (directories 0750,
  // files 0640; issue 16 found them 0644). The socket is made 0660 explicitly.
  ::umask(027);
  std::signal(SIGPIPE, SIG_IGN);
  scancell::daemon::DaemonConfig cfg;
  try {
    cfg = scancell::daemon::load_daemon_config(config, data_dir, socket);
  } catch (const scancell::ConfigError& e) {
    std::cerr << "scancelld: configuration refused: " << e.what() << "\n";
    return 4;
  } catch (const std::exception& e) {
    std::cerr << "scancelld: configuration refused: " << e.what() << "\n";
    return 4;
  }
  if (cfg.allowed_dirs.empty())
    std::cerr << "scancelld: jobs.allowed_dirs is not set: clients may name any regular file this daemon can read\n";
  std::cerr << "scancelld: scanner " << cfg.scanner_driver << ", profiles triggered by "
            << (cfg.jobs.drive_compare ? "the sweep drive's position compare" : "the daemon (polled sweep position)")
            << " (scanner.trigger_source)\n";
  try {
    scancell::daemon::Daemon d(std::move(cfg));
    return d.run();
  } catch (const std::exception& e) {
    std::cerr << "scancelld: cannot start: " << e.what() << "\n";
    return 1;
  }
}
