#pragma once
// The cell's hardware as the daemon drives it, composed from config/cells/*.yaml (axes, soft limits) and
// config/drivers/*.yaml (which bus each axis is on; trigger and interlock lines): a Positioner over Modbus,
// CANopen or in-process simulated drives, and the e-stop/door interlock when lines are configured.
#include <memory>
#include <string>
#include <vector>

#include "drivers/axis.hpp"
#include "drivers/config.hpp"
#include "drivers/gpio.hpp"
#include "drivers/sim/modbus_sim.hpp"
#include "planner/kinematics/cell.hpp"

namespace scancell::daemon {

struct CellIo {
  drivers::Positioner positioner;
  // "sim" axes: a drive simulator served on loopback Modbus TCP inside this process, driven through the same
  // ModbusAxis code as a real drive.
  std::vector<std::unique_ptr<drivers::sim::ModbusDriveSim>> sim_drives;
  std::unique_ptr<drivers::DigitalInput> estop, door;
  std::unique_ptr<drivers::Interlock> interlock;
};

/// Every cell axis must have a driver and every driver a cell axis (ConfigError naming both files). Soft
/// limits are the cell's axis ranges.
std::unique_ptr<CellIo> open_cell_io(const planner::CellModel& cell, const drivers::DriverSetup& setup,
                                     const std::string& drivers_file);

/// Stops an axis still finishing a move commanded before a crash, enables every axis, homes those that are
/// not homed (a restarted daemon finds its drives homed), then parks the cell at its home position.
void bring_up(CellIo& io, const planner::CellModel& cell, std::chrono::milliseconds timeout);

/// Moves every axis to the cell's home (SIGTERM, end of job).
void park(CellIo& io, const planner::CellModel& cell, std::chrono::milliseconds timeout);

}  // namespace scancell::daemon
