#pragma once
// One view on the cell: every axis to the start of the sweep, then the sweep at the scan speed with one
// trigger pulse each time the sweep passes the next profile position (software position compare; a drive's
// position-compare output does this in hardware). Each profile's pose is the kinematics at the position read
// back. Rows the sweep passed without a profile are swept again (up to JobSettings::fill_sweeps passes, the
// sweep axis alone back to the first of them, each at half the speed of the one before), firing only at
// them. Shared by the job runner and the calibration runs.
#include <atomic>
#include <functional>
#include <cstdint>
#include <string>
#include <vector>

#include "daemon/job_runner.hpp"

namespace scancell::daemon {

struct Acquisition {
  planner::RangeImage image;  // nominal pose at mid-sweep; samples carry their own measured positions
  int lost_profiles = 0;      // rows without a profile after every pass: passed between two reads, or lost by the scanner
  int fill_sweeps = 0;        // passes after the first, for the rows it left without a profile (JobSettings::fill_sweeps)
  int filled_profiles = 0;    // rows those passes acquired
};

/// `q`: the view's axis targets (sweep at the middle of its travel); `phase` is told "moving" and
/// "scanning". Throws Interrupted when `stop` asks (the sweep is halted, nothing is returned), DriverError
/// from the hardware.
Acquisition acquire_view(drivers::Positioner& positioner, ScanHead& head, const planner::CellModel& placed_cell,
                         const planner::SensorModel& sensor, const planner::JointVector& q, double scan_length_mm,
                         const JobSettings& settings, const std::atomic<int>& stop,
                         const std::function<void(const std::string&)>& phase = {});

/// The most profiles in a row the sweep passed without firing (0 when every row was acquired).
int longest_lost_run(const planner::RangeImage& image);

/// Of `rows` (indices into `points`, object frame, mm), those the sweep passed without a profile: the point
/// lies in the laser plane of a lost row or of a row next to it (eq. 3.8's density needs the profiles on both
/// sides). Where each row's plane lies is read from the image itself (its acquired profiles' y in the view
/// frame, fitted against the row index), so no cell model is needed and a stored scan answers the same.
/// A sweep with fewer than two acquired profiles holding samples passed every row.
std::vector<std::uint32_t> rows_passed_without_profile(const planner::RangeImage& image,
                                                       const std::vector<Eigen::Vector3d>& points,
                                                       const std::vector<std::uint32_t>& rows);

/// A measurement that must have no hole (calibration): a sweep that lost more than `max_gap_rows` profiles
/// in a row is taken again, up to `attempts` sweeps in all, each retake told to `log`. Returns the first take
/// without such a gap; when every take has one, the take with the shortest (the fits downstream then judge
/// whether it still serves). Single lost profiles are normal for a polled sweep and harmless to a fit; a run
/// of them is a stall that can hide a whole target (CI: a tripod sphere with 0 points). A lost profile is a
/// missed position compare, not a property of the target, so repeating the sweep is the remedy.
Acquisition take_whole(const std::function<Acquisition()>& take, int attempts, int max_gap_rows,
                       const std::function<void(const std::string&)>& log = {});

}  // namespace scancell::daemon
