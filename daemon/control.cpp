#include "daemon/control.hpp"

#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>
#include <stdexcept>

#include <grp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "common/json_input.hpp"

namespace scancell::daemon {
namespace {

using nlohmann::json;

enum class Type { string, integer, number, vec3 };
struct Field {
  Type type;
  bool required;
};

const std::map<std::string, std::map<std::string, Field>>& schema() {
  static const std::map<std::string, std::map<std::string, Field>> s = {
      {"submit", {{"mesh", {Type::string, false}}, {"bbox_mm", {Type::vec3, false}}, {"spec", {Type::string, false}}, {"settings", {Type::string, false}},
                  {"fit_mm", {Type::number, false}}, {"truth", {Type::string, false}},
                  {"rough_vertices", {Type::integer, false}}, {"placement", {Type::string, false}}, {"setups", {Type::integer, false}}}},
      {"status", {{"job", {Type::integer, false}}}},
      {"list", {}},
      {"record", {{"job", {Type::integer, true}}}},
      {"watch", {{"job", {Type::integer, true}}}},
      {"pause", {{"job", {Type::integer, true}}}},
      {"resume", {{"job", {Type::integer, true}}}},
      {"continue", {{"job", {Type::integer, true}}}},
      {"abort", {{"job", {Type::integer, true}}}},
      {"reload", {}},
      {"calibrate", {{"kind", {Type::string, true}}}},
  };
  return s;
}

const char* type_name(Type t) {
  return t == Type::string ? "a string" : t == Type::integer ? "an integer" : t == Type::number ? "a number" : "a list of 3 numbers";
}

bool has_type(const json& v, Type t) {
  switch (t) {
    case Type::string: return v.is_string();
    case Type::integer: return v.is_number_integer();
    case Type::number: return v.is_number();
    case Type::vec3: return v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() && v[2].is_number();
  }
  return false;
}

bool send_line(int fd, const json& j) {
  const std::string s = j.dump() + "\n";
  const char* p = s.data();
  std::size_t left = s.size();
  while (left) {
    const ssize_t n = ::send(fd, p, left, MSG_NOSIGNAL);
    if (n <= 0) {
      if (n < 0 && errno == EINTR) continue;
      return false;
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  return true;
}

}  // namespace

json parse_request(const std::string& line) {
  if (line.size() > kMaxRequestBytes) throw std::invalid_argument("request longer than 64 KiB");
  // Refused while parsing: a key given twice in one object (the last would win silently) and nesting deeper
  // than a request ever needs (the serializer recurses). No message echoes the request's own text.
  json j;
  try {
    j = scancell::parse_json_input(line, scancell::JsonLimits{16, true});
  } catch (const scancell::JsonInputError& e) {
    throw std::invalid_argument(std::string("request: ") + e.what());
  }
  if (!j.is_object()) throw std::invalid_argument("a request must be a JSON object");
  if (!j.contains("cmd") || !j["cmd"].is_string()) throw std::invalid_argument("missing \"cmd\" (a string)");
  const std::string cmd = j["cmd"];
  const auto it = schema().find(cmd);
  if (it == schema().end()) throw std::invalid_argument("unknown command '" + cmd + "'");
  for (const auto& [key, value] : j.items()) {
    if (key == "cmd") continue;
    const auto f = it->second.find(key);
    if (f == it->second.end()) throw std::invalid_argument(cmd + ": unknown field '" + key + "'");
    if (!has_type(value, f->second.type)) throw std::invalid_argument(cmd + ": field '" + key + "' must be " + type_name(f->second.type));
  }
  for (const auto& [key, f] : it->second)
    if (f.required && !j.contains(key)) throw std::invalid_argument(cmd + ": missing field '" + key + "'");
  return j;
}

ControlServer::ControlServer(std::filesystem::path path, Handler handler, ControlOptions options)
    : path_(std::move(path)), handler_(std::move(handler)), options_(std::move(options)) {
  if (options_.max_clients < 1) throw std::invalid_argument("control.max_clients must be at least 1");
  if (!(options_.idle_timeout_s > 0.0) || !(options_.send_timeout_s > 0.0))
    throw std::invalid_argument("control.idle_timeout_s and control.send_timeout_s must be > 0");
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path_.string().size() >= sizeof addr.sun_path) throw std::runtime_error(path_.string() + ": socket path too long");
  std::memcpy(addr.sun_path, path_.c_str(), path_.string().size() + 1);
  listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw std::runtime_error(path_.string() + ": socket: " + std::strerror(errno));
  ::unlink(path_.c_str());
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0 || ::listen(listen_fd_, 8) < 0) {
    const int e = errno;
    ::close(listen_fd_);
    throw std::runtime_error(path_.string() + ": bind/listen: " + std::strerror(e));
  }
  ::chmod(path_.c_str(), 0660);  // owner and group only
  const std::string& group = options_.group;
  if (!group.empty()) {
    const struct group* g = ::getgrnam(group.c_str());
    if (!g || ::chown(path_.c_str(), static_cast<uid_t>(-1), g->gr_gid) != 0) {
      ::close(listen_fd_);
      ::unlink(path_.c_str());
      throw std::runtime_error(path_.string() + ": cannot give the socket to group '" + group + "'");
    }
  }
  thread_ = std::thread([this] { accept_loop(); });
}

ControlServer::~ControlServer() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
  {
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (auto& c : clients_) c.thread.join();
  }
  ::close(listen_fd_);
  ::unlink(path_.c_str());
}

void ControlServer::accept_loop() {
  while (running_) {
    pollfd p{listen_fd_, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const int c = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (c < 0) continue;
    // A client that stops reading its replies is dropped after control.send_timeout_s, not waited for.
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(options_.send_timeout_s);
    tv.tv_usec = static_cast<suseconds_t>((options_.send_timeout_s - static_cast<double>(tv.tv_sec)) * 1e6);
    ::setsockopt(c, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (auto it = clients_.begin(); it != clients_.end();) {
      if (*it->done) {
        it->thread.join();
        it = clients_.erase(it);
      } else {
        ++it;
      }
    }
    if (clients_.size() >= static_cast<std::size_t>(options_.max_clients)) {
      ++turned_away_;
      send_line(c, {{"ok", false},
                    {"error", "too many clients: " + std::to_string(clients_.size()) + " connected (control.max_clients " +
                                  std::to_string(options_.max_clients) + "); try again later"}});
      ::close(c);
      continue;
    }
    auto done = std::make_shared<std::atomic<bool>>(false);
    clients_.push_back({std::thread([this, c, done] {
                          serve(c);
                          *done = true;
                        }),
                        done});
  }
}

void ControlServer::serve(int fd) {
  std::string buf;
  char chunk[4096];
  bool open = true;
  // A line over the limit is refused as soon as it is known to be too long; the rest of it, up to its newline,
  // is discarded as it arrives (never with a blocking read: a client that stalls there must not hold shutdown).
  bool skipping = false;
  using clock = std::chrono::steady_clock;
  auto last_request = clock::now();
  const auto idle = std::chrono::duration<double>(options_.idle_timeout_s);
  while (running_ && open) {
    if (clock::now() - last_request > idle) {
      ++dropped_idle_;
      std::ostringstream why;
      why << "no request for " << options_.idle_timeout_s << " s (control.idle_timeout_s): connection closed";
      send_line(fd, {{"ok", false}, {"error", why.str()}});
      break;
    }
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, chunk, sizeof chunk, MSG_DONTWAIT);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    if (n <= 0) break;
    const char* data = chunk;
    std::size_t size = static_cast<std::size_t>(n);
    if (skipping) {
      const char* nl = static_cast<const char*>(std::memchr(data, '\n', size));
      if (!nl) continue;
      skipping = false;
      size -= static_cast<std::size_t>(nl + 1 - data);
      data = nl + 1;
    }
    buf.append(data, size);
    if (buf.find('\n') == std::string::npos && buf.size() > kMaxRequestBytes) {
      ++refused_;
      open = send_line(fd, {{"ok", false}, {"error", "request longer than 64 KiB"}});
      buf.clear();
      skipping = true;
      last_request = clock::now();
      continue;
    }
    for (std::size_t nl; open && (nl = buf.find('\n')) != std::string::npos;) {
      const std::string line = buf.substr(0, nl);
      buf.erase(0, nl + 1);
      json reply;
      try {
        const json req = parse_request(line);
        reply = handler_(req, [&](const json& event) {
          open = open && send_line(fd, event);
          return open;
        });
        reply["ok"] = true;
      } catch (const std::invalid_argument& e) {
        ++refused_;
        reply = {{"ok", false}, {"error", e.what()}};
      } catch (const std::exception& e) {
        reply = {{"ok", false}, {"error", std::string("failed: ") + e.what()}};
      }
      open = open && send_line(fd, reply);
      last_request = clock::now();
    }
  }
  ::close(fd);
}

}  // namespace scancell::daemon
