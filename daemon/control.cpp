#include "daemon/control.hpp"

#include <cerrno>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <vector>
#include <stdexcept>

#include <grp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "planner/json_input.hpp"

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
                  {"rough_vertices", {Type::integer, false}}}},
      {"status", {{"job", {Type::integer, false}}}},
      {"list", {}},
      {"watch", {{"job", {Type::integer, true}}}},
      {"pause", {{"job", {Type::integer, true}}}},
      {"resume", {{"job", {Type::integer, true}}}},
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
    j = planner::parse_json_input(line, planner::JsonLimits{16, true});
  } catch (const planner::JsonInputError& e) {
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

ControlServer::ControlServer(std::filesystem::path path, Handler handler, const std::string& group)
    : path_(std::move(path)), handler_(std::move(handler)) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path_.string().size() >= sizeof addr.sun_path) throw std::runtime_error(path_.string() + ": socket path too long");
  std::memcpy(addr.sun_path, path_.c_str(), path_.string().size() + 1);
  listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM, 0);
  if (listen_fd_ < 0) throw std::runtime_error(path_.string() + ": socket: " + std::strerror(errno));
  ::unlink(path_.c_str());
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0 || ::listen(listen_fd_, 8) < 0) {
    const int e = errno;
    ::close(listen_fd_);
    throw std::runtime_error(path_.string() + ": bind/listen: " + std::strerror(e));
  }
  ::chmod(path_.c_str(), 0660);  // owner and group only
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
    const int c = ::accept(listen_fd_, nullptr, nullptr);
    if (c < 0) continue;
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (auto it = clients_.begin(); it != clients_.end();) {
      if (*it->done) {
        it->thread.join();
        it = clients_.erase(it);
      } else {
        ++it;
      }
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
  while (running_ && open) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
    if (n <= 0) break;
    buf.append(chunk, static_cast<std::size_t>(n));
    // A line longer than the limit is refused as soon as it is known to be too long, and dropped.
    if (buf.find('\n') == std::string::npos && buf.size() > kMaxRequestBytes) {
      ++refused_;
      open = send_line(fd, {{"ok", false}, {"error", "request longer than 64 KiB"}});
      buf.clear();
      // Skip the rest of that line.
      while (open && running_) {
        const ssize_t m = ::recv(fd, chunk, sizeof chunk, 0);
        if (m <= 0) { open = false; break; }
        const char* nl = static_cast<const char*>(std::memchr(chunk, '\n', static_cast<std::size_t>(m)));
        if (nl) {
          buf.assign(nl + 1, static_cast<std::size_t>(chunk + m - (nl + 1)));
          break;
        }
      }
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
    }
  }
  ::close(fd);
}

}  // namespace scancell::daemon
