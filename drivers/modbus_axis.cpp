#include "drivers/modbus_axis.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <thread>

#include <modbus/modbus.h>

#include "drivers/modbus_map.hpp"

namespace scancell::drivers {
namespace mm = modbus_map;

namespace {

bool transient(int err) { return err == ETIMEDOUT || err == EMBXSBUSY || err == EMBBADCRC || err == EMBXACK; }
/// A reply that does not answer the request sent (a late reply to an earlier request, a wrong function or
/// length): the link is out of step and must be resynchronised before it is trusted again.
bool out_of_step(int err) { return err == EMBBADDATA; }
bool connection_lost(int err) {
  return err == ECONNRESET || err == EPIPE || err == EBADF || err == ECONNREFUSED || err == ENOTCONN || err == EIO;
}

std::string register_name(int addr) {
  switch (addr) {
    case mm::kCommand: return "register 0 (command)";
    case mm::kStatus: return "register 1 (status)";
    case mm::kTargetHi: return "registers 2-3 (target)";
    case mm::kActualHi: return "registers 4-5 (actual position)";
    case mm::kVelocityHi: return "registers 6-7 (profile velocity)";
    default: return "register " + std::to_string(addr);
  }
}

const char* fault_name(std::uint16_t code) {
  switch (code) {
    case mm::kFollowingError: return "following error";
    case mm::kLimitHit: return "limit switch";
    case mm::kNotHomed: return "not homed";
    case mm::kNotEnabled: return "not enabled";
    default: return "drive fault";
  }
}

}  // namespace

const char* to_string(DriverError::Kind k) {
  switch (k) {
    case DriverError::Kind::timeout: return "timeout";
    case DriverError::Kind::exception: return "exception";
    case DriverError::Kind::connection: return "connection";
    case DriverError::Kind::protocol: return "protocol";
    case DriverError::Kind::fault: return "fault";
    case DriverError::Kind::refused: return "refused";
    case DriverError::Kind::motion_timeout: return "motion timeout";
  }
  return "?";
}

void Axis::arm_position_compare(double, double, int) {
  throw DriverError(DriverError::Kind::refused, name(), "position compare",
                    "this drive has no position-compare output (set scanner.trigger_source: daemon)");
}

int Axis::position_compare_fired() {
  throw DriverError(DriverError::Kind::refused, name(), "position compare",
                    "this drive has no position-compare output (set scanner.trigger_source: daemon)");
}

ModbusAxis::ModbusAxis(ModbusConfig config) : cfg_(std::move(config)) { connect(); }

ModbusAxis::~ModbusAxis() { close_link(); }

void ModbusAxis::close_link() {
  if (!ctx_) return;
  modbus_close(ctx_);
  modbus_free(ctx_);
  ctx_ = nullptr;
}

void ModbusAxis::connect() {
  close_link();
  ctx_ = cfg_.transport == ModbusConfig::Transport::tcp
             ? modbus_new_tcp(cfg_.host.c_str(), cfg_.port)
             : modbus_new_rtu(cfg_.device.c_str(), cfg_.baud, cfg_.parity, 8, 1);
  if (!ctx_) throw DriverError(DriverError::Kind::connection, cfg_.name, "context", std::strerror(errno));
  modbus_set_slave(ctx_, cfg_.unit_id);
  const auto us = std::chrono::duration_cast<std::chrono::microseconds>(cfg_.response_timeout).count();
  modbus_set_response_timeout(ctx_, static_cast<std::uint32_t>(us / 1000000), static_cast<std::uint32_t>(us % 1000000));
  if (modbus_connect(ctx_) != 0) {
    const std::string where = cfg_.transport == ModbusConfig::Transport::tcp
                                  ? cfg_.host + ":" + std::to_string(cfg_.port)
                                  : cfg_.device;
    const int err = errno;
    modbus_free(ctx_);
    ctx_ = nullptr;
    throw DriverError(DriverError::Kind::connection, cfg_.name, where, modbus_strerror(err));
  }
}

void ModbusAxis::fail(DriverError::Kind kind, const std::string& where, const std::string& cause) {
  faulted_ = true;
  throw DriverError(kind, cfg_.name, where, cause);
}

void ModbusAxis::refuse_if_faulted(const std::string& what) const {
  if (faulted_) throw DriverError(DriverError::Kind::refused, cfg_.name, what, "axis is faulted: reset_fault() first");
}

void ModbusAxis::pause(std::chrono::milliseconds d) {
  const auto until = std::chrono::steady_clock::now() + d;
  while (std::chrono::steady_clock::now() < until) {
    if (halt_waiting_) return;
    std::this_thread::sleep_for(std::min<std::chrono::milliseconds>(d, std::chrono::milliseconds(5)));
  }
}

void ModbusAxis::give_way_to_halt(const std::string& where) {
  if (halt_waiting_) fail(DriverError::Kind::connection, where, "gave way to a halt from another thread");
}

void ModbusAxis::reconnect(const std::string& where) {
  while (true) {
    if (reconnects_in_row_ >= cfg_.reconnect_attempts) {
      close_link();  // the next transaction starts with a connect, not on the dead link
      fail(DriverError::Kind::connection, where,
           "connection lost; " + std::to_string(reconnects_in_row_) +
               " reconnects in a row gave no working link (the peer accepts and drops it, or is gone; "
               "reconnect_attempts " + std::to_string(cfg_.reconnect_attempts) + ")");
    }
    pause(cfg_.reconnect_backoff * (1 << std::min(reconnects_in_row_, 10)));
    ++reconnects_in_row_;
    give_way_to_halt(where);
    try {
      connect();
      return;
    } catch (const DriverError&) {
    }
  }
}

void ModbusAxis::resync(const std::string& where) {
  if (cfg_.transport == ModbusConfig::Transport::tcp) {
    // A fresh connection: whatever late replies the old one still carries are gone with it.
    close_link();
    reconnect(where);
  } else {
    // One line: wait out what is still on its way, then drop it.
    pause(cfg_.response_timeout);
    modbus_flush(ctx_);
  }
}

void ModbusAxis::read(int addr, int n, std::uint16_t* out, const std::string& what) {
  // One transaction at a time on the context: the e-stop's halt may come from another thread mid-move.
  std::lock_guard<std::recursive_timed_mutex> lock(io_);
  if (!ctx_) reconnect(register_name(addr));
  for (int attempt = 0;; ++attempt) {
    if (modbus_read_registers(ctx_, addr, n, out) == n) {
      reconnects_in_row_ = 0;
      return;
    }
    const int err = errno;
    give_way_to_halt(register_name(addr));
    if (connection_lost(err)) {
      reconnect(register_name(addr));
      continue;  // reads are safe to repeat; reconnect() bounds how often
    }
    if (out_of_step(err)) {
      resync(register_name(addr));  // before retrying, and before giving up: the link must not stay shifted
      if (attempt < cfg_.retries) continue;
    }
    if (transient(err) && attempt < cfg_.retries) continue;
    fail(transient(err) ? DriverError::Kind::timeout : out_of_step(err) ? DriverError::Kind::protocol : DriverError::Kind::exception,
         register_name(addr), what + ": " + modbus_strerror(err));
  }
}

void ModbusAxis::write(int addr, int n, const std::uint16_t* values, const std::string& what) {
  std::lock_guard<std::recursive_timed_mutex> lock(io_);
  if (!ctx_) reconnect(register_name(addr));
  for (int attempt = 0;; ++attempt) {
    if (modbus_write_registers(ctx_, addr, n, values) == n) {
      reconnects_in_row_ = 0;
      return;
    }
    const int err = errno;
    if (connection_lost(err)) {
      // The write may or may not have reached the drive: reconnect, but let the caller decide from the state.
      reconnect(register_name(addr));
      fail(DriverError::Kind::connection, register_name(addr),
           what + ": connection lost during the write; reconnected, command not re-sent");
    }
    if (out_of_step(err)) {
      // The reply answered an earlier request; this write has most likely reached the drive. Resynchronise
      // so the next transaction (reset_fault, a state read) is answered by its own reply.
      resync(register_name(addr));
      fail(DriverError::Kind::protocol, register_name(addr),
           what + ": the reply did not answer this request (a late reply); link resynchronised, command not re-sent");
    }
    give_way_to_halt(register_name(addr));
    if (transient(err) && attempt < cfg_.retries) continue;
    fail(transient(err) ? DriverError::Kind::timeout : DriverError::Kind::exception, register_name(addr),
         what + ": " + modbus_strerror(err));
  }
}

void ModbusAxis::command(std::uint16_t cmd, const std::string& what) {
  const std::uint16_t v = cmd;
  write(mm::kCommand, 1, &v, what);
}

void ModbusAxis::arm_position_compare(double start, double pitch, int count) {
  refuse_if_faulted("position compare");
  if (!std::isfinite(start) || !std::isfinite(pitch) || pitch == 0.0 || count < 1 || count > 65535)
    fail(DriverError::Kind::refused, "registers 12-16 (position compare)",
         "start " + std::to_string(start) + ", pitch " + std::to_string(pitch) + ", count " + std::to_string(count) +
             ": needs a finite start, a non-zero pitch and 1 to 65535 positions");
  std::uint16_t r[5];
  mm::put_i32(r, 0, to_counts(cfg_.name, "compare start", start, cfg_.counts_per_unit));
  // The pitch in thousandths of a count: 700 profiles at 83.7 counts apart would drift 0.3 counts each at
  // whole counts, 210 counts over the sweep.
  mm::put_i32(r, 2, to_counts(cfg_.name, "compare pitch", pitch, 1000.0 * cfg_.counts_per_unit));
  r[4] = static_cast<std::uint16_t>(count);
  write(mm::kCompareStartHi, 5, r, "position compare");
  command(mm::kArmCompare, "arm position compare");
}

int ModbusAxis::position_compare_fired() {
  std::uint16_t r = 0;
  read(mm::kCompareFired, 1, &r, "position compare pulses");
  return r;
}

ModbusAxis::CompareState ModbusAxis::position_compare() {
  std::uint16_t r[8] = {};
  read(mm::kCompareStartHi, 8, r, "position compare");
  CompareState c;
  c.start = mm::get_i32(r, 0) / cfg_.counts_per_unit;
  c.pitch = mm::get_i32(r, 2) / (1000.0 * cfg_.counts_per_unit);
  c.count = r[4];
  c.fired = r[5];
  c.total = static_cast<std::uint32_t>(mm::get_i32(r, 6));
  return c;
}

AxisState ModbusAxis::state() {
  std::uint16_t r[mm::kStateCount] = {};
  read(0, mm::kStateCount, r, "state");
  AxisState s;
  s.position = mm::get_i32(r, mm::kActualHi) / cfg_.counts_per_unit;
  s.velocity = mm::get_i32(r, mm::kActualVelocityHi) / cfg_.counts_per_unit;
  s.enabled = r[mm::kStatus] & mm::kEnabled;
  s.homed = r[mm::kStatus] & mm::kHomed;
  s.moving = r[mm::kStatus] & mm::kMoving;
  s.in_position = r[mm::kStatus] & mm::kInPosition;
  s.faulted = (r[mm::kStatus] & mm::kFault) || faulted_;
  s.fault_code = r[mm::kFaultCode];
  return s;
}

void ModbusAxis::wait_for(std::uint16_t bits, std::chrono::milliseconds timeout, const std::string& what) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    std::uint16_t r[2] = {};
    read(mm::kStatus, 1, r, what);
    if (r[0] & mm::kFault) {
      std::uint16_t code = 0;
      read(mm::kFaultCode, 1, &code, what);
      fail(DriverError::Kind::fault, "register 1 (status)", what + ": drive reports " + fault_name(code));
    }
    if ((r[0] & bits) == bits && !(r[0] & mm::kMoving)) return;
    if (std::chrono::steady_clock::now() > deadline) {
      try {
        command(mm::kHalt, "halt after " + what + " timeout");
      } catch (const DriverError&) {
      }
      fail(DriverError::Kind::motion_timeout, "register 1 (status)", what + ": not done within " + std::to_string(timeout.count()) + " ms; halted");
    }
    std::this_thread::sleep_for(cfg_.poll_period);
  }
}

void ModbusAxis::enable() {
  refuse_if_faulted("enable");
  command(mm::kEnable, "enable");
  wait_for(mm::kEnabled, std::chrono::milliseconds(500), "enable");
}

void ModbusAxis::disable() { command(mm::kDisable, "disable"); }

void ModbusAxis::home(std::chrono::milliseconds timeout) {
  refuse_if_faulted("home");
  command(mm::kHome, "home");
  wait_for(mm::kHomed | mm::kInPosition, timeout, "home");
}

void ModbusAxis::begin_move(double target, double velocity) {
  refuse_if_faulted("move");
  check_move_request(cfg_.name, target, velocity);
  const std::int32_t counts = to_counts(cfg_.name, "move target", target, cfg_.counts_per_unit);
  const double v = velocity > 0.0 ? velocity : cfg_.profile_velocity;
  const std::int32_t vel = to_counts(cfg_.name, "move velocity", v, cfg_.counts_per_unit);
  std::uint16_t tv[2];
  mm::put_i32(tv, 0, counts);
  write(mm::kTargetHi, 2, tv, "move target");
  std::uint16_t vv[2];
  mm::put_i32(vv, 0, vel);
  write(mm::kVelocityHi, 2, vv, "move velocity");
  command(mm::kMove, "move");
}

void ModbusAxis::finish_move(double target, std::chrono::milliseconds timeout) {
  const auto counts = static_cast<std::int32_t>(std::llround(target * cfg_.counts_per_unit));
  wait_for(mm::kInPosition, timeout, "move to " + std::to_string(target));
  // In position but elsewhere: the move was stopped (halt, e-stop) before its target.
  std::uint16_t actual[2];
  read(mm::kActualHi, 2, actual, "move result");
  if (std::llabs(static_cast<long long>(mm::get_i32(actual, 0)) - counts) > 1)
    fail(DriverError::Kind::fault, "registers 4-5 (actual position)",
         "move to " + std::to_string(target) + " interrupted at " + std::to_string(mm::get_i32(actual, 0) / cfg_.counts_per_unit));
}

void ModbusAxis::stop() { command(mm::kStop, "stop"); }

void ModbusAxis::halt() {
  // A transaction of another thread may hold io_ for its retries and reconnects (seconds on a misbehaving
  // link): it sees halt_waiting_ at its next step and gives way, so the halt waits at most about one
  // response timeout for the lock.
  halt_waiting_ = true;
  std::unique_lock<std::recursive_timed_mutex> lock(io_, std::defer_lock);
  const auto wait = cfg_.response_timeout * 4 + std::chrono::milliseconds(100);
  const bool got = lock.try_lock_for(wait);
  halt_waiting_ = false;
  if (!got)
    throw DriverError(DriverError::Kind::timeout, cfg_.name, "halt",
                      "the link stayed busy for " + std::to_string(wait.count()) + " ms; halt not sent");
  command(mm::kHalt, "halt");
}

void ModbusAxis::reset_fault() {
  {
    std::lock_guard<std::recursive_timed_mutex> lock(io_);
    reconnects_in_row_ = 0;  // an explicit reset tries the link afresh
  }
  faulted_ = false;
  command(mm::kResetFault, "reset fault");
}

// ---- Positioner ----

void Positioner::add(std::unique_ptr<Axis> axis, SoftLimits limits) {
  const std::string n = axis->name();
  if (!(limits.min < limits.max)) throw DriverError(DriverError::Kind::refused, n, "soft limits", "min must be below max");
  axes_[n] = Entry{std::move(axis), limits};
}

Axis& Positioner::axis(const std::string& name) {
  auto it = axes_.find(name);
  if (it == axes_.end()) throw DriverError(DriverError::Kind::refused, name, "positioner", "no such axis");
  return *it->second.axis;
}

std::vector<std::string> Positioner::names() const {
  std::vector<std::string> out;
  for (const auto& [n, e] : axes_) out.push_back(n);
  return out;
}

std::vector<std::string> Positioner::latch_estop(const std::string& why) {
  latched_ = true;
  latch_reason_ = why;
  return halt_all();
}

void Positioner::reset_estop() { latched_ = false; }

void check_move_request(const std::string& axis, double target, double velocity) {
  if (!std::isfinite(target)) throw DriverError(DriverError::Kind::refused, axis, "move", "target is not finite");
  if (!std::isfinite(velocity) || velocity < 0.0)
    throw DriverError(DriverError::Kind::refused, axis, "move", "velocity is not a finite non-negative number");
}

std::int32_t to_counts(const std::string& axis, const std::string& what, double value, double counts_per_unit) {
  const double c = std::round(value * counts_per_unit);
  if (!(c >= -2147483648.0 && c <= 2147483647.0))
    throw DriverError(DriverError::Kind::refused, axis, what,
                      std::to_string(value) + " is " + std::to_string(c) +
                          " counts, outside the drive's 32-bit range (check counts_per_unit, " + std::to_string(counts_per_unit) + ")");
  return static_cast<std::int32_t>(c);
}

void Positioner::check_target(const std::string& n, double t) const {
  if (latched_)
    throw DriverError(DriverError::Kind::refused, "positioner", "e-stop", "latched (" + latch_reason_ + "): reset first");
  auto it = axes_.find(n);
  if (it == axes_.end()) throw DriverError(DriverError::Kind::refused, n, "move", "no such axis");
  const SoftLimits& l = it->second.limits;
  if (!(t >= l.min && t <= l.max))
    throw DriverError(DriverError::Kind::refused, n, "soft limit",
                      "target " + std::to_string(t) + " outside [" + std::to_string(l.min) + ", " + std::to_string(l.max) + "]");
}

void Positioner::begin_move(const std::string& name, double target, double velocity) {
  check_target(name, target);
  axes_.at(name).axis->begin_move(target, velocity);
}

void Positioner::move(const std::map<std::string, double>& targets, std::chrono::milliseconds timeout) {
  // Every target is checked before any command leaves the process.
  for (const auto& [n, t] : targets) check_target(n, t);
  // All axes move at once (the planner's move times assume it): one thread per axis, each with its own
  // transaction lock. If any axis fails, every axis is halted and the first error is reported.
  std::vector<std::thread> movers;
  std::vector<std::exception_ptr> errors(targets.size());
  std::size_t k = 0;
  for (const auto& [n, t] : targets) {
    Axis* a = axes_.at(n).axis.get();
    const double target = t;
    std::exception_ptr* slot = &errors[k++];
    movers.emplace_back([a, target, timeout, slot] {
      try {
        a->move_to(target, timeout);
      } catch (...) {
        *slot = std::current_exception();
      }
    });
  }
  for (auto& m : movers) m.join();
  for (const auto& e : errors)
    if (e) {
      halt_all();
      std::rethrow_exception(e);
    }
}

std::vector<std::string> Positioner::halt_all() {
  // Every axis at once: one misbehaving link must not delay the halt of the others.
  std::vector<std::string> slots(axes_.size());
  std::vector<std::thread> haltors;
  std::size_t k = 0;
  for (auto& [n, e] : axes_) {
    Axis* a = e.axis.get();
    std::string* slot = &slots[k++];
    haltors.emplace_back([a, slot] {
      try {
        a->halt();
      } catch (const std::exception& err) {
        *slot = err.what();
      }
    });
  }
  for (auto& t : haltors) t.join();
  std::vector<std::string> errors;
  for (auto& s : slots)
    if (!s.empty()) errors.push_back(std::move(s));
  return errors;
}

}  // namespace scancell::drivers
