#pragma once
// The daemon's control socket: a Unix domain socket (mode 0660, optional group), one JSON request per line,
// one JSON reply per line. Requests are checked before anything acts on them: at most 64 KiB, valid JSON, a
// known "cmd", only that command's fields, each of its type. A bad request gets {"ok": false, "error": ...}
// naming what is wrong; the server keeps running.
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

class ControlServer {
 public:
  /// `handler` answers a valid request with the reply object (without "ok"; it is added). For `watch`, the
  /// handler may call `send` repeatedly before returning to stream events; `send` returns false once the
  /// client has gone (the handler should then return).
  using Handler = std::function<nlohmann::json(const nlohmann::json& request,
                                               const std::function<bool(const nlohmann::json&)>& send)>;
  ControlServer(std::filesystem::path socket_path, Handler handler, const std::string& group = "");
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;
  std::size_t refused() const { return refused_; }

 private:
  void accept_loop();
  void serve(int fd);

  std::filesystem::path path_;
  Handler handler_;
  int listen_fd_ = -1;
  std::atomic<bool> running_{true};
  std::atomic<std::size_t> refused_{0};
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
