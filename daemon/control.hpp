#pragma once
// The daemon's control socket: a Unix domain socket (mode 0660, optional group), one JSON request per line,
// one JSON reply per line. Requests are checked before anything acts on them: at most 64 KiB, valid JSON, a
// known "cmd", only that command's fields, each of its type. A bad request gets {"ok": false, "error": ...}
// naming what is wrong; the server keeps running. No client can hold the server: every read and write is
// bounded (poll with the stop flag, idle and send timeouts) and connections are capped, so the daemon stops
// within its budget whatever clients do (issue 16, defect 4).
//
// Commands and fields (required unless marked optional):
//   submit   mesh (string) or bbox_mm (3 numbers: start with a rough scan), spec (string, optional), settings (string, optional), fit_mm (number, optional),
//            truth (string, optional; simulation: the object actually on the table), rough_vertices (integer, optional)
//   status   job (integer, optional)
//   list     —
//   watch    job (integer)            — the reply is followed by event lines until the job ends
//   pause | resume | abort   job (integer)
//   reload   —
//   calibrate  kind (string: sensor | turntable_axis | positioner)
#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

namespace scancell::daemon {

/// Validates one request line; returns the parsed request or throws std::invalid_argument with the reason.
nlohmann::json parse_request(const std::string& line);

inline constexpr std::size_t kMaxRequestBytes = 64 * 1024;

/// The config's `control` section beyond the socket path (docs/daemon.md).
struct ControlOptions {
  std::string group;            ///< control.group: group given the socket ("" keeps the daemon's)
  int max_clients = 32;         ///< control.max_clients: connections served at once; more are refused with a reply
  double idle_timeout_s = 300;  ///< control.idle_timeout_s: a client that sends no request this long is dropped
  double send_timeout_s = 5;    ///< control.send_timeout_s: a client that does not read its replies this long is dropped
};

class ControlServer {
 public:
  /// `handler` answers a valid request with the reply object (without "ok"; it is added). For `watch`, the
  /// handler may call `send` repeatedly before returning to stream events; `send` returns false once the
  /// client has gone (the handler should then return).
  using Handler = std::function<nlohmann::json(const nlohmann::json& request,
                                               const std::function<bool(const nlohmann::json&)>& send)>;
  ControlServer(std::filesystem::path socket_path, Handler handler, ControlOptions options = {});
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;
  std::size_t refused() const { return refused_; }
  /// Connections refused because control.max_clients were connected, and clients dropped for idling.
  std::size_t turned_away() const { return turned_away_; }
  std::size_t dropped_idle() const { return dropped_idle_; }

 private:
  void accept_loop();
  void serve(int fd);

  std::filesystem::path path_;
  Handler handler_;
  int listen_fd_ = -1;
  std::atomic<bool> running_{true};
  ControlOptions options_;
  std::atomic<std::size_t> refused_{0}, turned_away_{0}, dropped_idle_{0};
  std::thread thread_;
  std::mutex clients_mu_;
  // One thread per connected client; finished ones are joined as new clients arrive (a daemon that runs for
  // weeks must not collect threads).
  struct Client {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::vector<Client> clients_;
};

}  // namespace scancell::daemon
