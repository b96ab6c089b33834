#include "daemon/cell_io.hpp"

#include <cmath>
#include <map>
#include <thread>

#include "drivers/canopen_axis.hpp"
#include "drivers/modbus_axis.hpp"
#include "common/errors.hpp"

namespace scancell::daemon {

namespace dr = scancell::drivers;
namespace sp = scancell::planner;

std::unique_ptr<CellIo> open_cell_io(const sp::CellModel& cell, const dr::DriverSetup& setup, const std::string& drivers_file) {
  auto io = std::make_unique<CellIo>();
  for (const auto& [name, cfg] : setup.axes) {
    bool known = false;
    for (const auto& a : cell.axes) known = known || a.name == name;
    if (!known) throw scancell::ConfigError(drivers_file + ": axes." + name + ": cell '" + cell.name + "' has no such axis");
  }
  for (const auto& a : cell.axes) {
    const auto it = setup.axes.find(a.name);
    if (it == setup.axes.end()) throw scancell::ConfigError(drivers_file + ": axes: no driver for cell axis '" + a.name + "'");
    std::unique_ptr<dr::Axis> axis;
    if (const auto* m = std::get_if<dr::ModbusConfig>(&it->second)) {
      dr::ModbusConfig c = *m;
      c.name = a.name;
      axis = std::make_unique<dr::ModbusAxis>(c);
    } else if (const auto* co = std::get_if<dr::CanOpenAxisConfig>(&it->second)) {
      axis = std::make_unique<dr::CanOpenAxis>(co->axis, dr::CanLink::open(co->interface));
    } else {
      // In-process simulated drive: 1 µm or 10 µrad per count, fast enough for the axis' configured speed.
      const double counts = a.type == sp::AxisType::rotary ? 100000.0 : 1000.0;
      dr::sim::DriveParams p;
      p.max_velocity_counts_s = 2.0 * a.max_speed * counts;
      p.accel_counts_s2 = a.max_accel * counts;
      p.min_counts = static_cast<std::int32_t>(std::floor(std::min(a.min, 0.0) * counts)) - 1000;
      p.max_counts = static_cast<std::int32_t>(std::ceil(std::max(a.max, 0.0) * counts)) + 1000;
      auto drive = std::make_unique<dr::sim::ModbusDriveSim>(p, 1);
      const int port = drive->serve_tcp(16000 + static_cast<int>(io->sim_drives.size()) * 7);
      dr::ModbusConfig c;
      c.name = a.name;
      c.port = port;
      c.counts_per_unit = counts;
      c.profile_velocity = a.max_speed;
      c.poll_period = std::chrono::milliseconds(1);
      io->sim_drives.push_back(std::move(drive));
      axis = std::make_unique<dr::ModbusAxis>(c);
    }
    io->positioner.add(std::move(axis), {a.min, a.max});
  }
  auto line_in = [](const dr::LineConfig& l) -> std::unique_ptr<dr::DigitalInput> {
    if (l.chip == "sim") return std::make_unique<dr::SimInput>(!l.active_high);  // released
    return std::make_unique<dr::GpiodInput>(l.chip, l.offset);
  };
  if (setup.estop) {
    io->estop = line_in(*setup.estop);
    if (setup.door) io->door = line_in(*setup.door);
    io->interlock = std::make_unique<dr::Interlock>(*io->estop, io->door.get(), io->positioner, setup.estop->active_high);
  }
  return io;
}

void bring_up(CellIo& io, const sp::CellModel& cell, std::chrono::milliseconds timeout) {
  for (const auto& a : cell.axes) {
    dr::Axis& axis = io.positioner.axis(a.name);
    dr::AxisState s = axis.state();
    // A daemon that died mid-move left the drive finishing that move: stop it and wait for standstill
    // before anything else is commanded.
    if (s.moving) {
      axis.stop();
      const auto deadline = std::chrono::steady_clock::now() + timeout;
      while ((s = axis.state()).moving) {
        if (std::chrono::steady_clock::now() > deadline)
          throw dr::DriverError(dr::DriverError::Kind::motion_timeout, a.name, "start-up", "still moving after a stop");
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    }
    if (s.faulted) axis.reset_fault();
    axis.enable();
    if (!axis.state().homed) axis.home(timeout);
  }
  park(io, cell, timeout);
}

void park(CellIo& io, const sp::CellModel& cell, std::chrono::milliseconds timeout) {
  std::map<std::string, double> home;
  for (const auto& a : cell.axes) home[a.name] = a.home;
  io.positioner.move(home, timeout);
}

}  // namespace scancell::daemon
