#pragma once
// One view on the cell: every axis to the start of the sweep, then the sweep at the scan speed with one
// trigger pulse each time the sweep passes the next profile position (software position compare; a drive's
// position-compare output does this in hardware). Each profile's pose is the kinematics at the position read
// back. Shared by the job runner and the calibration runs.
#include <atomic>
#include <functional>
#include <string>

#include "daemon/job_runner.hpp"

namespace scancell::daemon {

struct Acquisition {
  planner::RangeImage image;  // nominal pose at mid-sweep; samples carry their own measured positions
  int lost_profiles = 0;      // profile positions passed between two reads of the sweep
};

/// `q`: the view's axis targets (sweep at the middle of its travel); `phase` is told "moving" and
/// "scanning". Throws Interrupted when `stop` asks (the sweep is halted, nothing is returned), DriverError
/// from the hardware.
Acquisition acquire_view(drivers::Positioner& positioner, ScanHead& head, const planner::CellModel& placed_cell,
                         const planner::SensorModel& sensor, const planner::JointVector& q, double scan_length_mm,
                         const JobSettings& settings, const std::atomic<int>& stop,
                         const std::function<void(const std::string&)>& phase = {});

/// A measurement that must be whole (calibration): a sweep that lost profiles is taken again, up to
/// `attempts` times in all, each retake told to `log`. Returns the first complete take; when every take lost
/// profiles, the one that lost fewest (the fits downstream then judge whether it still serves). A lost profile
/// is a missed position compare, not a property of the target, so repeating the sweep is the remedy.
Acquisition take_whole(const std::function<Acquisition()>& take, int attempts,
                       const std::function<void(const std::string&)>& log = {});

}  // namespace scancell::daemon
