#include "drivers/canopen_axis.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <thread>

#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

namespace scancell::drivers {
namespace {

using Clock = std::chrono::steady_clock;

// CiA 402 objects and bits.
constexpr std::uint16_t kControlword = 0x6040, kStatusword = 0x6041, kModes = 0x6060, kTarget = 0x607A,
                        kProfileVelocity = 0x6081, kPositionActual = 0x6064, kVelocityActual = 0x606C,
                        kErrorCode = 0x603F;
constexpr std::uint16_t kSwReady = 1u << 0, kSwSwitchedOn = 1u << 1, kSwOpEnabled = 1u << 2, kSwFault = 1u << 3,
                        kSwTargetReached = 1u << 10, kSwSetpointAck = 1u << 12, kSwFollowingError = 1u << 13;
constexpr std::uint16_t kCwShutdown = 0x06, kCwSwitchOn = 0x07, kCwEnableOp = 0x0F, kCwNewSetpoint = 0x10,
                        kCwHalt = 0x100, kCwQuickStop = 0x02, kCwFaultReset = 0x80, kCwDisableVoltage = 0x00;

std::string hex(std::uint32_t v, int width) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%0*X", width, v);
  return b;
}

std::string object_name(std::uint16_t index, std::uint8_t sub) { return "object " + hex(index, 4) + ":" + std::to_string(sub); }

}  // namespace

can_frame sdo_frame(std::uint32_t cob_id, std::uint8_t command, std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  can_frame f{};
  f.can_id = cob_id;
  f.can_dlc = 8;
  f.data[0] = command;
  f.data[1] = index & 0xFF;
  f.data[2] = index >> 8;
  f.data[3] = sub;
  for (int k = 0; k < 4; ++k) f.data[4 + k] = (value >> (8 * k)) & 0xFF;
  return f;
}

std::uint32_t sdo_value(const can_frame& f) {
  std::uint32_t v = 0;
  for (int k = 0; k < 4; ++k) v |= static_cast<std::uint32_t>(f.data[4 + k]) << (8 * k);
  return v;
}

std::string sdo_abort_text(std::uint32_t code) {
  switch (code) {
    case 0x05040000: return "SDO protocol timed out";
    case 0x05040001: return "command specifier not valid";
    case 0x06010000: return "unsupported access to an object";
    case 0x06010002: return "attempt to write a read only object";
    case 0x06020000: return "object does not exist in the object dictionary";
    case 0x06070010: return "data type does not match";
    case 0x06090011: return "sub-index does not exist";
    case 0x06090030: return "value range of parameter exceeded";
    case 0x08000000: return "general error";
    case 0x08000022: return "data cannot be transferred because of the present device state";
    default: return "abort code " + hex(code, 8);
  }
}

CanLink::~CanLink() {
  if (fd_ >= 0) ::close(fd_);
}

int CanLink::open_socketcan(const std::string& interface) {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) throw DriverError(DriverError::Kind::connection, interface, "socket(PF_CAN)", std::strerror(errno));
  ifreq ifr{};
  std::snprintf(ifr.ifr_name, IFNAMSIZ, "%s", interface.c_str());
  if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    const int e = errno;
    ::close(fd);
    throw DriverError(DriverError::Kind::connection, interface, "SIOCGIFINDEX", std::strerror(e));
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int e = errno;
    ::close(fd);
    throw DriverError(DriverError::Kind::connection, interface, "bind", std::strerror(e));
  }
  return fd;
}

int CanLink::open_unix(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
  if (fd < 0) throw DriverError(DriverError::Kind::connection, path, "socket(AF_UNIX)", std::strerror(errno));
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof addr.sun_path) {
    ::close(fd);
    throw DriverError(DriverError::Kind::connection, path, "connect", "path too long for a Unix socket");
  }
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int e = errno;
    ::close(fd);
    throw DriverError(DriverError::Kind::connection, path, "connect", std::strerror(e));
  }
  return fd;
}

int CanLink::open(const std::string& interface) {
  return interface.rfind("unix:", 0) == 0 ? open_unix(interface.substr(5)) : open_socketcan(interface);
}

void CanLink::send(const can_frame& f) {
  if (::write(fd_, &f, sizeof f) != static_cast<ssize_t>(sizeof f))
    throw DriverError(DriverError::Kind::connection, "can", "write", errno ? std::strerror(errno) : "short write");
}

bool CanLink::receive(can_frame& f, std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  const int r = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (r == 0) return false;
  if (r < 0) throw DriverError(DriverError::Kind::connection, "can", "poll", std::strerror(errno));
  const ssize_t n = ::read(fd_, &f, sizeof f);
  if (n == 0 || (p.revents & POLLHUP)) throw DriverError(DriverError::Kind::connection, "can", "read", "bus gone (peer closed)");
  if (n != static_cast<ssize_t>(sizeof f)) throw DriverError(DriverError::Kind::protocol, "can", "read", "short frame");
  return true;
}

CanOpenAxis::CanOpenAxis(CanOpenConfig config, int fd) : cfg_(std::move(config)), link_(fd) {
  last_heartbeat_ = Clock::now();
}

void CanOpenAxis::fail(DriverError::Kind kind, const std::string& where, const std::string& cause) {
  faulted_ = true;
  throw DriverError(kind, cfg_.name, where, cause);
}

void CanOpenAxis::refuse_if_faulted(const std::string& what) const {
  if (faulted_) throw DriverError(DriverError::Kind::refused, cfg_.name, what, "axis is faulted: reset_fault() first");
}

void CanOpenAxis::absorb(const can_frame& f) {
  if (f.can_id == static_cast<canid_t>(0x700 + cfg_.node_id)) {
    last_heartbeat_ = Clock::now();
    heartbeat_seen_ = true;
  }
}

void CanOpenAxis::check_heartbeat(const std::string& what) {
  if (heartbeat_seen_ && Clock::now() - last_heartbeat_ > cfg_.heartbeat_timeout)
    fail(DriverError::Kind::fault, "heartbeat " + hex(0x700 + cfg_.node_id, 3),
         what + ": no heartbeat for " + std::to_string(cfg_.heartbeat_timeout.count()) + " ms");
}

void CanOpenAxis::nmt(std::uint8_t command) {
  can_frame f{};
  f.can_id = 0x000;
  f.can_dlc = 2;
  f.data[0] = command;
  f.data[1] = static_cast<std::uint8_t>(cfg_.node_id);
  link_.send(f);
}

can_frame CanOpenAxis::sdo_transfer(std::uint8_t command, std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                                    const std::string& where) {
  for (int attempt = 0;; ++attempt) {
    link_.send(sdo_frame(static_cast<canid_t>(0x600 + cfg_.node_id), command, index, sub, value));
    const auto deadline = Clock::now() + cfg_.sdo_timeout;
    can_frame r{};
    while (Clock::now() < deadline) {
      if (!link_.receive(r, std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()) + std::chrono::milliseconds(1))) break;
      absorb(r);  // heartbeats and other traffic arrive in between
      if (r.can_id != static_cast<canid_t>(0x580 + cfg_.node_id)) continue;
      // A reply names its object: one for another request (late, after a retry, or duplicated) is stale. Taken
      // as the answer, it would shift every later read by one transaction.
      if (static_cast<std::uint16_t>(r.data[1] | (r.data[2] << 8)) != index || r.data[3] != sub) {
        ++stale_sdo_replies_;
        continue;
      }
      if (r.data[0] == 0x80) fail(DriverError::Kind::exception, where, "SDO abort: " + sdo_abort_text(sdo_value(r)));
      return r;
    }
    check_heartbeat("SDO " + where);
    if (attempt >= cfg_.sdo_retries) fail(DriverError::Kind::timeout, where, "no SDO reply");
  }
}

void CanOpenAxis::sdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value, int bytes) {
  std::lock_guard<std::mutex> lock(io_);  // one SDO transaction at a time (an e-stop halt may come from another thread)
  const std::string where = object_name(index, sub);
  // Expedited download with the size indicated: 0x23 (4 bytes), 0x27 (3), 0x2B (2), 0x2F (1).
  const can_frame r = sdo_transfer(static_cast<std::uint8_t>(0x23 | ((4 - bytes) << 2)), index, sub, value, where);
  if (r.data[0] != 0x60) fail(DriverError::Kind::protocol, where, "unexpected SDO reply " + hex(r.data[0], 2));
}

std::uint32_t CanOpenAxis::sdo_read(std::uint16_t index, std::uint8_t sub) {
  std::lock_guard<std::mutex> lock(io_);
  const std::string where = object_name(index, sub);
  const can_frame r = sdo_transfer(0x40, index, sub, 0, where);  // expedited upload request
  if ((r.data[0] & 0xE3) != 0x43) fail(DriverError::Kind::protocol, where, "unexpected SDO reply " + hex(r.data[0], 2));
  return sdo_value(r);
}

std::uint16_t CanOpenAxis::statusword() { return static_cast<std::uint16_t>(sdo_read(kStatusword, 0)); }

void CanOpenAxis::wait_status(std::uint16_t mask, std::uint16_t value, std::chrono::milliseconds timeout,
                              const std::string& what) {
  const auto deadline = Clock::now() + timeout;
  while (true) {
    check_heartbeat(what);
    const std::uint16_t sw = statusword();
    if (sw & kSwFault) {
      const auto code = sdo_read(kErrorCode, 0);
      fail(DriverError::Kind::fault, "statusword 0x6041", what + ": drive fault, error code " + hex(code, 4) +
                                                              ((sw & kSwFollowingError) ? " (following error)" : ""));
    }
    if (sw & kSwFollowingError) fail(DriverError::Kind::fault, "statusword 0x6041", what + ": following error");
    if ((sw & mask) == value) return;
    if (Clock::now() > deadline) {
      try {
        sdo_write(kControlword, 0, kCwQuickStop, 2);
      } catch (const DriverError&) {
      }
      fail(DriverError::Kind::motion_timeout, "statusword 0x6041", what + ": not done within " + std::to_string(timeout.count()) + " ms; quick stop sent");
    }
    std::this_thread::sleep_for(cfg_.poll_period);
  }
}

void CanOpenAxis::enable() {
  refuse_if_faulted("enable");
  nmt(0x01);  // start remote node: operational
  if (statusword() & kSwFault) sdo_write(kControlword, 0, kCwFaultReset, 2);
  sdo_write(kControlword, 0, kCwShutdown, 2);
  wait_status(kSwReady, kSwReady, std::chrono::milliseconds(500), "shutdown -> ready to switch on");
  sdo_write(kControlword, 0, kCwSwitchOn, 2);
  wait_status(kSwSwitchedOn, kSwSwitchedOn, std::chrono::milliseconds(500), "switch on");
  sdo_write(kControlword, 0, kCwEnableOp, 2);
  wait_status(kSwOpEnabled, kSwOpEnabled, std::chrono::milliseconds(500), "enable operation");
}

void CanOpenAxis::disable() { sdo_write(kControlword, 0, kCwDisableVoltage, 2); }

void CanOpenAxis::home(std::chrono::milliseconds timeout) {
  refuse_if_faulted("home");
  sdo_write(kModes, 0, 6, 1);  // homing mode
  sdo_write(kControlword, 0, kCwEnableOp | kCwNewSetpoint, 2);  // bit 4: start homing
  wait_status(kSwTargetReached | kSwSetpointAck, kSwTargetReached | kSwSetpointAck, timeout, "home");
  sdo_write(kControlword, 0, kCwEnableOp, 2);
  homed_ = true;
}

void CanOpenAxis::begin_move(double target, double velocity) {
  refuse_if_faulted("move");
  check_move_request(cfg_.name, target, velocity);
  const std::int32_t counts = to_counts(cfg_.name, "move target", target, cfg_.counts_per_unit);
  const double v = velocity > 0.0 ? velocity : cfg_.profile_velocity;
  const std::int32_t vel = to_counts(cfg_.name, "move velocity", v, cfg_.counts_per_unit);  // before anything is sent
  sdo_write(kModes, 0, 1, 1);  // profile position
  sdo_write(kTarget, 0, static_cast<std::uint32_t>(counts), 4);
  sdo_write(kProfileVelocity, 0, static_cast<std::uint32_t>(vel), 4);
  // New set-point handshake: raise bit 4, wait for the acknowledge, lower it; finish_move waits for the target.
  sdo_write(kControlword, 0, kCwEnableOp | kCwNewSetpoint, 2);
  wait_status(kSwSetpointAck, kSwSetpointAck, std::chrono::milliseconds(500), "set-point acknowledge");
  sdo_write(kControlword, 0, kCwEnableOp, 2);
}

void CanOpenAxis::finish_move(double target, std::chrono::milliseconds timeout) {
  wait_status(kSwTargetReached | kSwSetpointAck, kSwTargetReached, timeout, "move to " + std::to_string(target));
}

void CanOpenAxis::stop() { sdo_write(kControlword, 0, kCwEnableOp | kCwHalt, 2); }

void CanOpenAxis::halt() { sdo_write(kControlword, 0, kCwQuickStop, 2); }

void CanOpenAxis::reset_fault() {
  faulted_ = false;
  heartbeat_seen_ = false;
  sdo_write(kControlword, 0, kCwFaultReset, 2);
}

AxisState CanOpenAxis::state() {
  AxisState s;
  const std::uint16_t sw = statusword();
  s.position = static_cast<std::int32_t>(sdo_read(kPositionActual, 0)) / cfg_.counts_per_unit;
  s.velocity = static_cast<std::int32_t>(sdo_read(kVelocityActual, 0)) / cfg_.counts_per_unit;
  s.enabled = sw & kSwOpEnabled;
  s.in_position = sw & kSwTargetReached;
  s.moving = !(sw & kSwTargetReached) && s.enabled;
  s.faulted = (sw & kSwFault) || faulted_;
  s.homed = homed_;
  return s;
}

}  // namespace scancell::drivers
