#include "drivers/sim/cia402_sim.hpp"

#include <optional>

#include "drivers/canopen_axis.hpp"

#include <chrono>
#include <cmath>
#include <cstring>

#include <linux/can.h>
#include <poll.h>
#include <unistd.h>

namespace scancell::drivers::sim {
namespace {
using Clock = std::chrono::steady_clock;
constexpr std::uint32_t kAbortNoObject = 0x06020000, kAbortReadOnly = 0x06010002, kAbortState = 0x08000022;
}  // namespace

Cia402DriveSim::Cia402DriveSim(int fd, int node_id, Cia402Params params) : fd_(fd), node_(node_id), p_(params) {
  thread_ = std::thread([this] { run(); });
}

Cia402DriveSim::~Cia402DriveSim() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
  if (fd_ >= 0) ::close(fd_);
}

void Cia402DriveSim::inject(CanFault f) {
  std::lock_guard<std::mutex> lock(mu_);
  fault_ = f;
  if (f == CanFault::drive_fault) {
    state_ = State::fault;
    error_code_ = 0x2310;  // continuous over-current
    moving_ = false;
  }
}

std::vector<CanLogEntry> Cia402DriveSim::writes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return log_;
}

std::int32_t Cia402DriveSim::actual_counts() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<std::int32_t>(std::lround(pos_));
}

std::uint16_t Cia402DriveSim::statusword() const {
  std::uint16_t sw = 0;
  switch (state_) {
    case State::disabled: sw = 1u << 6; break;
    case State::ready: sw = 0x21; break;
    case State::switched_on: sw = 0x23; break;
    case State::enabled: sw = 0x27; break;
    case State::fault: sw = 0x08; break;
  }
  if (reached_ && !moving_ && homing_left_ <= 0.0) sw |= 1u << 10;
  if (ack_) sw |= 1u << 12;
  if (following_) sw |= 1u << 13;
  return sw;
}

void Cia402DriveSim::step(double dt) {
  if (homing_left_ > 0.0) {
    homing_left_ -= dt;
    if (homing_left_ <= 0.0) {
      pos_ = 0.0;
      target_ = 0;
      reached_ = true;
      ack_ = true;  // homing attained (bit 12 in homing mode)
    }
    return;
  }
  if (!moving_) return;
  const double d = target_ - pos_;
  const double dir = d >= 0 ? 1.0 : -1.0;
  const double brake = vel_ * vel_ / (2.0 * p_.accel_counts_s2);
  const double vmax = std::min<double>(p_.max_velocity_counts_s, velocity_obj_ > 0 ? velocity_obj_ : p_.max_velocity_counts_s);
  if (std::abs(d) <= brake + 1e-9) vel_ = std::max(0.0, vel_ - p_.accel_counts_s2 * dt);
  else vel_ = std::min(vmax, vel_ + p_.accel_counts_s2 * dt);
  const double s = vel_ * dt;
  if (s >= std::abs(d) || (vel_ == 0.0 && std::abs(d) < 1.0)) {
    pos_ = target_;
    vel_ = 0.0;
    moving_ = false;
    reached_ = true;
  } else {
    pos_ += dir * s;
  }
}

void Cia402DriveSim::reply_sdo(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  const can_frame f = sdo_frame(static_cast<canid_t>(0x580 + node_), cmd, index, sub, value);
  (void)!::write(fd_, &f, sizeof f);
  if (fault_ == CanFault::duplicate_reply_once) {
    fault_ = CanFault::none;
    (void)!::write(fd_, &f, sizeof f);
  }
}

/// SDO upload (read) of an object this drive has; nothing for one it lacks.
std::optional<std::uint32_t> Cia402DriveSim::upload(std::uint16_t index) const {
  std::uint32_t v = 0;
  switch (index) {
    case 0x6041: v = statusword(); break;
    case 0x6040: v = control_; break;
    case 0x6060: case 0x6061: v = static_cast<std::uint8_t>(mode_); break;
    case 0x607A: v = static_cast<std::uint32_t>(target_obj_); break;
    case 0x6081: v = velocity_obj_; break;
    case 0x6064: v = static_cast<std::uint32_t>(static_cast<std::int32_t>(std::lround(pos_))); break;
    case 0x606C: v = static_cast<std::uint32_t>(static_cast<std::int32_t>(std::lround(vel_))); break;
    case 0x603F: v = error_code_; break;
    default: return std::nullopt;
  }
  return v;
}

/// A controlword (0x6040) written: the CiA 402 state machine, and in operation enabled a new set-point on
/// bit 4's rising edge (profile position: a move; homing: the homing run).
void Cia402DriveSim::controlword(std::uint16_t value) {
  const std::uint16_t prev = control_;
  control_ = static_cast<std::uint16_t>(value);
  const bool rising4 = (control_ & 0x10) && !(prev & 0x10);
  if ((control_ & 0x80) && !(prev & 0x80)) {  // fault reset
    if (state_ == State::fault) state_ = State::disabled, error_code_ = 0, following_ = false;
    return;
  }
  if (state_ == State::fault) return;
  if ((control_ & 0x87) == 0x02 || (control_ & 0x82) == 0x00) {  // quick stop or disable voltage
    moving_ = false;
    vel_ = 0.0;
    target_ = static_cast<std::int32_t>(std::lround(pos_));
    pos_ = target_;
    reached_ = true;
    state_ = State::disabled;
    return;
  }
  if ((control_ & 0x87) == 0x06) state_ = State::ready;
  else if ((control_ & 0x8F) == 0x07 && state_ == State::ready) state_ = State::switched_on;
  else if ((control_ & 0x8F) == 0x0F && (state_ == State::switched_on || state_ == State::enabled)) state_ = State::enabled;
  if (state_ != State::enabled) return;
  if (control_ & 0x100) {  // halt
    moving_ = false;
    vel_ = 0.0;
    target_ = static_cast<std::int32_t>(std::lround(pos_));
    pos_ = target_;
    reached_ = true;
    return;
  }
  if (!(control_ & 0x10)) {
    if (mode_ == 1) ack_ = false;
    return;
  }
  if (!rising4) return;
  if (mode_ == 6) {
    homing_left_ = p_.home_time_s;
    ack_ = false;
    reached_ = false;
  } else if (mode_ == 1) {
    if (target_obj_ < p_.min_counts || target_obj_ > p_.max_counts) {
      ++violations_;
      state_ = State::fault;
      error_code_ = 0x8612;  // reference limit
      return;
    }
    ack_ = true;
    if (fault_ == CanFault::following_error) {
      fault_ = CanFault::none;
      following_ = true;
      state_ = State::fault;
      error_code_ = 0x8611;  // following error
      return;
    }
    target_ = target_obj_;
    moving_ = std::lround(pos_) != target_;
    reached_ = !moving_;
  }
}

void Cia402DriveSim::on_frame(const can_frame& frame) {
  const unsigned char* d = frame.data;
  const std::uint32_t id = frame.can_id;
  std::lock_guard<std::mutex> lock(mu_);
  if (id == 0x000) return;  // NMT: every state is "operational" enough for this drive
  if (id != static_cast<std::uint32_t>(0x600 + node_)) return;
  const std::uint16_t index = static_cast<std::uint16_t>(d[1] | (d[2] << 8));
  const std::uint8_t sub = d[3];
  const std::uint32_t value = sdo_value(frame);
  if (fault_ == CanFault::sdo_abort_once) {
    fault_ = CanFault::none;
    reply_sdo(0x80, index, sub, kAbortState);
    return;
  }
  const int ccs = d[0] >> 5;
  if (ccs == 2) {  // upload
    const auto v = upload(index);
    if (v) reply_sdo(0x43, index, sub, *v);
    else reply_sdo(0x80, index, sub, kAbortNoObject);
    return;
  }
  if (ccs != 1) {
    reply_sdo(0x80, index, sub, 0x05040001);
    return;
  }
  log_.push_back({index, value});
  switch (index) {
    case 0x6040: controlword(static_cast<std::uint16_t>(value)); break;
    case 0x6060: mode_ = static_cast<std::int8_t>(value & 0xFF); break;
    case 0x607A: target_obj_ = static_cast<std::int32_t>(value); break;
    case 0x6081: velocity_obj_ = value; break;
    case 0x6041: case 0x6064: case 0x606C: case 0x603F: reply_sdo(0x80, index, sub, kAbortReadOnly); return;
    default: reply_sdo(0x80, index, sub, kAbortNoObject); return;
  }
  reply_sdo(0x60, index, sub, 0);
}

void Cia402DriveSim::run() {
  auto last = Clock::now();
  while (running_) {
    if (fault_ == CanFault::bus_off) {
      ::close(fd_);  // the drive vanishes from the bus
      fd_ = -1;
      return;
    }
    pollfd pf{fd_, POLLIN, 0};
    const int r = ::poll(&pf, 1, 2);
    const auto now = Clock::now();
    const double dt = std::chrono::duration<double>(now - last).count();
    last = now;
    {
      std::lock_guard<std::mutex> lock(mu_);
      step(dt);
      heartbeat_left_ -= dt;
      if (heartbeat_left_ <= 0.0) {
        heartbeat_left_ = p_.heartbeat_period_s;
        if (fault_ != CanFault::missing_heartbeat) {
          can_frame hb{};
          hb.can_id = static_cast<canid_t>(0x700 + node_);
          hb.can_dlc = 1;
          hb.data[0] = 0x05;  // operational
          (void)!::write(fd_, &hb, sizeof hb);
        }
      }
    }
    if (r > 0 && (pf.revents & POLLIN)) {
      can_frame f{};
      const ssize_t n = ::read(fd_, &f, sizeof f);
      if (n <= 0) return;
      if (n == static_cast<ssize_t>(sizeof f)) on_frame(f);
    }
  }
}

}  // namespace scancell::drivers::sim
