#include "drivers/sim/modbus_sim.hpp"
#include <algorithm>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <pty.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include "drivers/modbus_map.hpp"

namespace scancell::drivers::sim {
namespace mm = modbus_map;

namespace {
modbus_mapping_t* map_of(void* p) { return static_cast<modbus_mapping_t*>(p); }
using Clock = std::chrono::steady_clock;
}  // namespace

ModbusDriveSim::ModbusDriveSim(DriveParams params, int unit_id) : p_(params), unit_(unit_id) {
  mapping_ = modbus_mapping_new(0, 0, mm::kCount, 0);
  if (!mapping_) throw std::runtime_error("modbus sim: cannot allocate the register map");
}

ModbusDriveSim::~ModbusDriveSim() {
  stop();
  modbus_mapping_free(map_of(mapping_));
}

void ModbusDriveSim::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
  for (int* fd : {&listen_fd_, &pty_master_, &pty_slave_})
    if (*fd >= 0) ::close(*fd), *fd = -1;
}

std::vector<LoggedCommand> ModbusDriveSim::commands() const {
  std::lock_guard<std::mutex> lock(mu_);
  return log_;
}

std::int32_t ModbusDriveSim::actual_counts() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<std::int32_t>(std::lround(pos_));
}

int ModbusDriveSim::serve_tcp(int first_port) {
  for (int port = first_port; port < first_port + 200; ++port) {
    modbus_t* ctx = modbus_new_tcp("127.0.0.1", port);
    const int fd = modbus_tcp_listen(ctx, 1);
    if (fd >= 0) {
      listen_fd_ = fd;
      server_ctx_ = ctx;
      running_ = true;
      thread_ = std::thread([this, fd] { run_tcp(fd); });
      return port;
    }
    modbus_free(ctx);
  }
  throw std::runtime_error("modbus sim: no free TCP port");
}

std::string ModbusDriveSim::serve_rtu() {
  char name[256] = {};
  if (::openpty(&pty_master_, &pty_slave_, name, nullptr, nullptr) != 0)
    throw std::runtime_error(std::string("modbus sim: openpty: ") + std::strerror(errno));
  termios t{};
  ::tcgetattr(pty_master_, &t);
  ::cfmakeraw(&t);
  ::tcsetattr(pty_master_, TCSANOW, &t);
  // libmodbus needs a device name for an RTU context; the server speaks on the pty master it is given.
  modbus_t* ctx = modbus_new_rtu("/dev/null", 115200, 'N', 8, 1);
  modbus_set_slave(ctx, unit_);
  modbus_set_socket(ctx, pty_master_);
  server_ctx_ = ctx;
  running_ = true;
  rtu_ = true;
  const int fd = pty_master_;
  thread_ = std::thread([this, fd] { run_rtu(fd); });
  return name;
}

void ModbusDriveSim::fire_compare() {
  // The compare output pulses once for every compare position the axis has reached in the direction of the
  // pitch, however many one cycle passes (a drive compares in hardware, far faster than its bus cycle).
  while (compare_fired_ < compare_count_) {
    const double at = compare_start_ + compare_fired_ * compare_pitch_;
    if (compare_pitch_ > 0.0 ? pos_ < at - 0.5 : pos_ > at + 0.5) break;
    ++compare_fired_;
    ++compare_total_;
  }
  auto* regs = map_of(mapping_)->tab_registers;
  regs[mm::kCompareFired] = static_cast<std::uint16_t>(compare_fired_);
  mm::put_i32(regs, mm::kCompareTotalHi, static_cast<std::int32_t>(compare_total_));
}

int ModbusDriveSim::compare_fired() const {
  std::lock_guard<std::mutex> lock(mu_);
  return compare_fired_;
}

void ModbusDriveSim::step(double dt) {
  std::lock_guard<std::mutex> lock(mu_);
  ++heartbeat_;
  if (homing_left_ > 0.0) {
    homing_left_ -= dt;
    if (homing_left_ <= 0.0) {
      pos_ = 0.0;
      target_ = 0;
      homed_ = true;
      moving_ = false;
    }
  } else if (moving_ && !stalled_) {
    // Trapezoidal profile: accelerate to max velocity, brake to stop on the target.
    const double d = target_ - pos_;
    const double dir = d >= 0 ? 1.0 : -1.0;
    const double brake = vel_ * vel_ / (2.0 * p_.accel_counts_s2);
    // The commanded profile velocity (registers 6-7), capped by the drive's own maximum.
    const double profile = mm::get_i32(map_of(mapping_)->tab_registers, mm::kVelocityHi);
    const double vmax = profile > 0.0 ? std::min(profile, p_.max_velocity_counts_s) : p_.max_velocity_counts_s;
    if (std::abs(d) <= brake + 1e-9) vel_ = std::max(0.0, vel_ - p_.accel_counts_s2 * dt);
    else vel_ = std::min(vmax, vel_ + p_.accel_counts_s2 * dt);
    double stepc = vel_ * dt;
    if (stepc >= std::abs(d) || (vel_ == 0.0 && std::abs(d) < 1.0)) {
      pos_ = target_;
      vel_ = 0.0;
      moving_ = false;
    } else {
      pos_ += dir * stepc;
    }
  }
  fire_compare();
  auto* regs = map_of(mapping_)->tab_registers;
  std::uint16_t st = 0;
  if (enabled_) st |= mm::kEnabled;
  if (homed_) st |= mm::kHomed;
  if (moving_ || homing_left_ > 0.0) st |= mm::kMoving;
  if (!moving_ && homing_left_ <= 0.0 && std::lround(pos_) == target_) st |= mm::kInPosition;
  if (fault_bit_) st |= mm::kFault;
  regs[mm::kStatus] = st;
  mm::put_i32(regs, mm::kActualHi, static_cast<std::int32_t>(std::lround(pos_)));
  mm::put_i32(regs, mm::kActualVelocityHi, static_cast<std::int32_t>(std::lround(vel_)));
  regs[mm::kFaultCode] = fault_code_;
  regs[mm::kHeartbeat] = heartbeat_;
}

unsigned ModbusDriveSim::refuse_write(void* ctxv, const std::uint8_t* req, int len) const {
  auto* ctx = static_cast<modbus_t*>(ctxv);
  const int off = modbus_get_header_length(ctx);  // unit id (RTU) or MBAP header (TCP), then the function
  if (len < off + 5) return 0;
  const int function = req[off];
  if (function != 0x06 && function != 0x10) return 0;
  const int addr = (req[off + 1] << 8) | req[off + 2];
  const int count = function == 0x06 ? 1 : ((req[off + 3] << 8) | req[off + 4]);
  auto writable = [](int a) {
    return a == mm::kCommand || a == mm::kTargetHi || a == mm::kTargetHi + 1 || a == mm::kVelocityHi || a == mm::kVelocityHi + 1 ||
           (a >= mm::kCompareStartHi && a <= mm::kCompareCount);
  };
  for (int a = addr; a < addr + count; ++a)
    if (a >= mm::kCount || !writable(a)) return MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
  // A write of the velocity's high word (function 16, both words) with the sign bit set: negative.
  if (function == 0x10 && addr <= mm::kVelocityHi && addr + count > mm::kVelocityHi) {
    const int k = off + 6 + 2 * (mm::kVelocityHi - addr);  // values follow the byte count
    if (k < len && (req[k] & 0x80)) return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
  }
  return 0;
}

/// An injected fault that answers the request itself, or withholds the answer: true when it did. A late
/// reply only waits, then the request is answered as usual.
bool ModbusDriveSim::answer_fault(void* ctxv, const std::uint8_t* req, ModbusFault f) {
  auto* ctx = static_cast<modbus_t*>(ctxv);
  if (f == ModbusFault::no_reply) return true;
  if (f == ModbusFault::illegal_address) {
    modbus_reply_exception(ctx, req, MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS);
    return true;
  }
  if (f == ModbusFault::device_failure) {
    modbus_reply_exception(ctx, req, MODBUS_EXCEPTION_SLAVE_OR_SERVER_FAILURE);
    return true;
  }
  if (f == ModbusFault::corrupt_once && rtu_) {
    // A well-formed reply of the right length whose CRC is wrong: the client must reject it (EMBBADCRC).
    fault_ = ModbusFault::none;
    const int function = req[1];
    std::uint8_t out[MODBUS_RTU_MAX_ADU_LENGTH];
    int n = 0;
    out[n++] = static_cast<std::uint8_t>(unit_);
    out[n++] = static_cast<std::uint8_t>(function);
    if (function == 0x03) {
      const int count = (req[4] << 8) | req[5];
      out[n++] = static_cast<std::uint8_t>(2 * count);
      for (int k = 0; k < 2 * count; ++k) out[n++] = 0;
    } else {
      for (int k = 2; k < 6; ++k) out[n++] = req[k];
    }
    out[n++] = 0xDE;  // not the CRC of what precedes
    out[n++] = 0xAD;
    (void)!::write(pty_master_, out, static_cast<std::size_t>(n));
    ++corrupt_sent_;
    return true;
  }
  if (f == ModbusFault::late_reply_once) {
    fault_ = ModbusFault::none;
    std::this_thread::sleep_for(std::chrono::milliseconds(150));  // then answered as usual, too late
  }
  if (f == ModbusFault::busy_once) {
    fault_ = ModbusFault::none;
    modbus_reply_exception(ctx, req, MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY);
    return true;
  }
  return false;
}

/// A command written to the command register, executed as a drive does (under mu_); false: drop the
/// connection (an injected fault).
bool ModbusDriveSim::execute(std::uint16_t cmd, std::int32_t target, ModbusFault f) {
  bool keep = true;
  switch (cmd) {
    case mm::kEnable: enabled_ = true; break;
    case mm::kDisable: enabled_ = false; moving_ = false; vel_ = 0.0; break;
    case mm::kHome:
      if (!enabled_) { fault_bit_ = true; fault_code_ = mm::kNotEnabled; break; }
      homing_left_ = p_.home_time_s;
      break;
    case mm::kMove:
      if (target < p_.min_counts || target > p_.max_counts) {
        ++violations_;  // the driver must never send this: the tests assert it stays 0
        fault_bit_ = true;
        fault_code_ = mm::kLimitHit;
        break;
      }
      if (!enabled_ || !homed_) { fault_bit_ = true; fault_code_ = enabled_ ? mm::kNotHomed : mm::kNotEnabled; break; }
      if (f == ModbusFault::following_error) {
        fault_ = ModbusFault::none;
        fault_bit_ = true;
        fault_code_ = mm::kFollowingError;
        break;
      }
      target_ = target;
      moving_ = std::lround(pos_) != target_;
      stalled_ = f == ModbusFault::stall;
      if (f == ModbusFault::drop_connection) {
        fault_ = ModbusFault::none;
        keep = false;
      }
      break;
    case mm::kStop:
    case mm::kHalt:
      target_ = static_cast<std::int32_t>(std::lround(pos_));
      pos_ = target_;
      moving_ = false;
      vel_ = 0.0;
      stalled_ = false;
      break;
    case mm::kResetFault: fault_bit_ = false; fault_code_ = mm::kNoFault; break;
    case mm::kArmCompare: {
      const auto* regs = map_of(mapping_)->tab_registers;
      compare_start_ = mm::get_i32(regs, mm::kCompareStartHi);
      compare_pitch_ = mm::get_i32(regs, mm::kComparePitchHi) / 1000.0;
      compare_count_ = compare_pitch_ != 0.0 ? regs[mm::kCompareCount] : 0;
      compare_fired_ = 0;
      fire_compare();  // standing on the first position fires it
      break;
    }
    default: break;
  }
  return keep;
}

bool ModbusDriveSim::handle(void* ctxv, const std::uint8_t* req, int len) {
  auto* ctx = static_cast<modbus_t*>(ctxv);
  const ModbusFault f = fault_;
  if (answer_fault(ctx, req, f)) return true;
  // As strict as a drive: a write that touches a read-only register (status, actual position and velocity,
  // fault code, heartbeat) is answered with exception 2, and a negative profile velocity with exception 3;
  // neither changes anything.
  if (const auto refused = refuse_write(ctx, req, len)) {
    ++refused_writes_;
    modbus_reply_exception(ctx, req, refused);
    return true;
  }
  std::lock_guard<std::mutex> lock(mu_);
  modbus_reply(ctx, req, len, map_of(mapping_));
  auto* regs = map_of(mapping_)->tab_registers;
  const std::uint16_t cmd = regs[mm::kCommand];
  if (cmd == mm::kNone) return true;
  regs[mm::kCommand] = mm::kNone;
  const std::int32_t target = mm::get_i32(regs, mm::kTargetHi);
  log_.push_back({cmd, target, std::chrono::steady_clock::now()});
  return execute(cmd, target, f);
}

void ModbusDriveSim::run_tcp(int listen_fd) {
  // Several clients at once, as a drive's Modbus TCP server takes them (the daemon, and a simulated scanner
  // reading the compare counter its compare output would pulse), each request answered in turn.
  auto* ctx = static_cast<modbus_t*>(server_ctx_);
  std::uint8_t req[MODBUS_TCP_MAX_ADU_LENGTH];
  auto last = Clock::now();
  std::vector<int> clients;
  auto drop = [&](int c) {
    ::close(c);
    clients.erase(std::remove(clients.begin(), clients.end(), c), clients.end());
  };
  while (running_) {
    fd_set set;
    FD_ZERO(&set);
    FD_SET(listen_fd, &set);
    int maxfd = listen_fd;
    for (int c : clients) FD_SET(c, &set), maxfd = std::max(maxfd, c);
    timeval tv{0, 2000};
    const int n = ::select(maxfd + 1, &set, nullptr, nullptr, &tv);
    const auto now = Clock::now();
    step(std::chrono::duration<double>(now - last).count());
    last = now;
    const bool dropping = fault_ == ModbusFault::accept_and_close;
    if (dropping)
      while (!clients.empty()) drop(clients.back());
    if (n <= 0) continue;
    if (FD_ISSET(listen_fd, &set)) {
      const int c = ::accept(listen_fd, nullptr, nullptr);
      if (c >= 0 && (dropping || clients.size() >= 8)) ::close(c);
      else if (c >= 0) clients.push_back(c);
    }
    for (const int c : std::vector<int>(clients)) {
      if (!FD_ISSET(c, &set)) continue;
      modbus_set_socket(ctx, c);
      const int len = modbus_receive(ctx, req);
      if (len <= 0 || !handle(ctx, req, len)) drop(c);
    }
  }
  for (const int c : clients) ::close(c);
  modbus_free(ctx);
  server_ctx_ = nullptr;
}

void ModbusDriveSim::run_rtu(int master_fd) {
  auto* ctx = static_cast<modbus_t*>(server_ctx_);
  std::uint8_t req[MODBUS_RTU_MAX_ADU_LENGTH];
  auto last = Clock::now();
  while (running_) {
    fd_set set;
    FD_ZERO(&set);
    FD_SET(master_fd, &set);
    timeval tv{0, 2000};
    const int n = ::select(master_fd + 1, &set, nullptr, nullptr, &tv);
    const auto now = Clock::now();
    step(std::chrono::duration<double>(now - last).count());
    last = now;
    if (n <= 0) continue;
    const int len = modbus_receive(ctx, req);
    if (len > 0) handle(ctx, req, len);
  }
  modbus_set_socket(ctx, -1);
  modbus_free(ctx);
  server_ctx_ = nullptr;
}

}  // namespace scancell::drivers::sim
