// scancell-sim: the cell's drives, served over the real protocols for the daemon, the demo and manual tests.
//   scancell-sim modbus (--tcp PORT [--drives N] | --rtu) [--fault F] [--max-velocity COUNTS_S] [--accel COUNTS_S2]
//                       [--no-stdin]
//   scancell-sim can --unix PATH [--node N]
//   scancell-sim scanner --gige ADDRESS --mesh FILE --cell FILE --sensor FILE --drivers FILE [--fit-mm N] ...
//                       (tools/sim_scanner.cpp: a GigE Vision scanner triggered by the sweep drive's compare)
// Serves simulated Modbus drives (docs/modbus-register-map.md): N of them on 127.0.0.1:PORT ... PORT+N-1 (one
// per port, as a cell's drives each have their own address), or one on a new pseudo-terminal with --rtu (its
// path is printed). Faults can be chosen at start (--fault, every drive) or at run time by writing "FAULT" (drive
// 0) or "K FAULT" (drive K) to standard input: none, no_reply, illegal_address, busy_once, device_failure,
// stall, drop_connection, following_error, corrupt_once (RTU: a reply with a wrong CRC), accept_and_close,
// late_reply_once. --no-stdin: run until
// SIGINT/SIGTERM whatever standard input does (background use, the demo).
// `can` serves one simulated CiA 402 drive (node N, default 1) on a SOCK_SEQPACKET Unix socket at PATH carrying
// struct can_frame records (the drivers' CanLink::open("unix:PATH")); faults from standard input: none,
// sdo_abort_once, missing_heartbeat, drive_fault, following_error, bus_off. Runs until standard input closes
// or SIGINT/SIGTERM.
#include <csignal>
#include <cstring>
#include <iostream>
#include <map>
#include <optional>
#include <variant>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "drivers/sim/cia402_sim.hpp"
#include "drivers/sim/modbus_sim.hpp"
#include "tools/sim_scanner.hpp"

namespace sim = scancell::drivers::sim;

namespace {
volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

const std::map<std::string, sim::ModbusFault> kFaults = {
    {"none", sim::ModbusFault::none},
    {"no_reply", sim::ModbusFault::no_reply},
    {"illegal_address", sim::ModbusFault::illegal_address},
    {"busy_once", sim::ModbusFault::busy_once},
    {"device_failure", sim::ModbusFault::device_failure},
    {"stall", sim::ModbusFault::stall},
    {"drop_connection", sim::ModbusFault::drop_connection},
    {"following_error", sim::ModbusFault::following_error},
    {"corrupt_once", sim::ModbusFault::corrupt_once},
    {"accept_and_close", sim::ModbusFault::accept_and_close},
    {"late_reply_once", sim::ModbusFault::late_reply_once},
};

const std::map<std::string, sim::CanFault> kCanFaults = {
    {"none", sim::CanFault::none},
    {"sdo_abort_once", sim::CanFault::sdo_abort_once},
    {"missing_heartbeat", sim::CanFault::missing_heartbeat},
    {"drive_fault", sim::CanFault::drive_fault},
    {"following_error", sim::CanFault::following_error},
    {"bus_off", sim::CanFault::bus_off},
};

int usage() {
  std::cerr << "usage: scancell-sim can --unix PATH [--node N]\n";
  std::cerr << "usage: scancell-sim scanner --gige ADDRESS --mesh FILE --cell FILE --sensor FILE --drivers FILE [--fit-mm N] "
               "[--serial S] [--seed N]\n";
  std::cerr << "usage: scancell-sim modbus (--tcp PORT [--drives N] | --rtu) [--fault F] [--max-velocity COUNTS_S] "
               "[--accel COUNTS_S2] [--no-stdin]\n  faults:";
  for (const auto& [n, f] : kFaults) std::cerr << ' ' << n;
  std::cerr << "\n";
  return 2;
}

int serve_can(int argc, char** argv) {
  std::string path;
  int node = 1;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--unix" && i + 1 < argc) path = argv[++i];
    else if (a == "--node" && i + 1 < argc) node = std::atoi(argv[++i]);
    else return usage();
  }
  if (path.empty() || node < 1 || node > 127) return usage();
  const int lfd = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (lfd < 0 || path.size() >= sizeof addr.sun_path) {
    std::cerr << "scancell-sim: cannot make a Unix socket at " << path << "\n";
    return 1;
  }
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  ::unlink(path.c_str());
  if (::bind(lfd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0 || ::listen(lfd, 1) < 0) {
    std::cerr << "scancell-sim: " << path << ": " << std::strerror(errno) << "\n";
    return 1;
  }
  std::cout << "scancell-sim: CiA 402 drive node " << node << " on unix:" << path << std::endl;
  std::unique_ptr<sim::Cia402DriveSim> drive;
  std::string line;
  while (!g_stop) {
    pollfd p[2] = {{lfd, POLLIN, 0}, {0, POLLIN, 0}};
    if (::poll(p, 2, 100) <= 0) continue;
    if (p[0].revents & POLLIN) {
      const int c = ::accept(lfd, nullptr, nullptr);
      if (c >= 0) drive = std::make_unique<sim::Cia402DriveSim>(c, node);  // one client: a new one replaces it
    }
    if (p[1].revents & (POLLIN | POLLHUP)) {
      if (!std::getline(std::cin, line)) break;
      auto it = kCanFaults.find(line);
      if (it == kCanFaults.end() || !drive) {
        std::cerr << "scancell-sim: " << (drive ? "unknown fault '" + line + "'" : std::string("no client yet")) << "\n";
        continue;
      }
      drive->inject(it->second);
      std::cout << "scancell-sim: fault " << line << std::endl;
    }
  }
  const std::size_t violations = drive ? drive->limit_violations() : 0;
  drive.reset();
  ::close(lfd);
  ::unlink(path.c_str());
  return violations == 0 ? 0 : 1;
}

/// `scancell-sim modbus`'s options.
struct ModbusOptions {
  int port = 0, drives = 1;
  bool rtu = false, use_stdin = true;
  sim::DriveParams params;
  sim::ModbusFault fault = sim::ModbusFault::none;
};

/// The options, or the exit code after saying what is wrong.
std::variant<ModbusOptions, int> parse_modbus(int argc, char** argv) {
  ModbusOptions o;
  auto number = [&](int& i, const char* what) -> std::optional<double> {
    char* end = nullptr;
    const double v = std::strtod(argv[++i], &end);
    if (*end || !(v > 0.0)) {
      std::cerr << "scancell-sim: " << what << ": '" << argv[i] << "' is not a positive number\n";
      return std::nullopt;
    }
    return v;
  };
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--tcp" && has_value) {
      char* end = nullptr;
      o.port = static_cast<int>(std::strtol(argv[++i], &end, 10));
      if (*end || o.port <= 0 || o.port > 65535) {
        std::cerr << "scancell-sim: --tcp: '" << argv[i] << "' is not a port\n";
        return 2;
      }
    } else if (a == "--drives" && has_value) {
      const auto v = number(i, "--drives");
      if (!v) return 2;
      o.drives = static_cast<int>(*v);
      if (o.drives < 1 || o.drives > 32) {
        std::cerr << "scancell-sim: --drives must be in [1, 32]\n";
        return 2;
      }
    } else if ((a == "--max-velocity" || a == "--accel") && has_value) {
      const auto v = number(i, a.c_str());
      if (!v) return 2;
      (a == "--accel" ? o.params.accel_counts_s2 : o.params.max_velocity_counts_s) = *v;
    } else if (a == "--no-stdin") {
      o.use_stdin = false;
    } else if (a == "--rtu") {
      o.rtu = true;
    } else if (a == "--fault" && has_value) {
      auto it = kFaults.find(argv[++i]);
      if (it == kFaults.end()) {
        std::cerr << "scancell-sim: --fault: unknown fault '" << argv[i] << "'\n";
        return usage();
      }
      o.fault = it->second;
    } else {
      std::cerr << "scancell-sim: unknown option '" << a << "'\n";
      return usage();
    }
  }
  if (!o.rtu && o.port == 0) return usage();
  if (o.rtu && o.drives != 1) {
    std::cerr << "scancell-sim: --drives is for --tcp\n";
    return 2;
  }
  return o;
}

/// Until a signal (or the end of standard input): "[drive] fault" lines switch a drive's fault.
void fault_console(const std::vector<std::unique_ptr<sim::ModbusDriveSim>>& drive, bool use_stdin) {
  std::string line;
  while (!g_stop) {
    if (!use_stdin) {
      ::poll(nullptr, 0, 100);
      continue;
    }
    pollfd p{0, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    if (!std::getline(std::cin, line)) break;
    std::size_t k = 0;
    std::string name = line;
    if (const auto sp = line.find(' '); sp != std::string::npos) {
      k = static_cast<std::size_t>(std::atoi(line.substr(0, sp).c_str()));
      name = line.substr(sp + 1);
    }
    auto it = kFaults.find(name);
    if (it == kFaults.end() || k >= drive.size()) {
      std::cerr << "scancell-sim: unknown fault or drive '" << line << "'\n";
      continue;
    }
    drive[k]->inject(it->second);
    std::cout << "scancell-sim: drive " << k << " fault " << name << std::endl;
  }
}

int serve_modbus(int argc, char** argv) {
  const auto parsed = parse_modbus(argc, argv);
  if (const int* code = std::get_if<int>(&parsed)) return *code;
  const ModbusOptions& o = std::get<ModbusOptions>(parsed);
  std::vector<std::unique_ptr<sim::ModbusDriveSim>> drive;
  try {
    for (int k = 0; k < o.drives; ++k) {
      drive.push_back(std::make_unique<sim::ModbusDriveSim>(o.params));
      drive.back()->inject(o.fault);
      if (o.rtu) {
        std::cout << "scancell-sim: Modbus RTU on " << drive.back()->serve_rtu() << std::endl;
      } else {
        const int got = drive.back()->serve_tcp(o.port + k);
        if (got != o.port + k) throw std::runtime_error("port " + std::to_string(o.port + k) + " is taken");
        std::cout << "scancell-sim: Modbus TCP drive " << k << " on 127.0.0.1:" << got << std::endl;
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "scancell-sim: " << e.what() << "\n";
    return 1;
  }
  fault_console(drive, o.use_stdin);
  std::size_t commands = 0, violations = 0;
  for (const auto& d : drive) {
    commands += d->commands().size();
    violations += d->limit_violations();
  }
  std::cout << "scancell-sim: " << commands << " commands served, " << violations << " limit violations" << std::endl;
  return violations == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  // Every server runs until SIGINT/SIGTERM (or its own end): one pair of handlers for all.
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (argc >= 2 && std::strcmp(argv[1], "can") == 0) return serve_can(argc, argv);
  if (argc >= 2 && std::strcmp(argv[1], "modbus") == 0) return serve_modbus(argc, argv);
  if (argc >= 2 && std::strcmp(argv[1], "scanner") == 0) return scancell::tools::serve_scanner(argc, argv, g_stop);
  return usage();
}
