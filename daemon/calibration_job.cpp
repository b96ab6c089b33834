#include "daemon/calibration_job.hpp"

#include <algorithm>
#include <map>

#include "calibration/results.hpp"
#include "calibration/runs.hpp"
#include "calibration/targets.hpp"
#include "daemon/acquire.hpp"
#include "common/errors.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;
namespace cal = scancell::calibration;
using nlohmann::json;

/// Sweeps per calibration scan before its best take is fitted as it is, and the longest run of lost profiles
/// a take may have (see take_whole): on an idle machine a third of the sweeps lose 1-7 profiles, singly.
constexpr int kCalibrationScanAttempts = 3;
constexpr int kCalibrationMaxGapRows = 4;

void check_calibration_kind(const std::string& kind) {
  if (kind != "sensor" && kind != "turntable_axis" && kind != "positioner")
    throw std::invalid_argument("calibrate: kind must be sensor, turntable_axis or positioner, got '" + kind + "'");
}

JobState run_calibration_job(Journal& journal, std::int64_t job, const std::string& kind, CellModels& models,
                             drivers::Positioner& positioner, const ScanHeadFactory& heads, const JobSettings& settings,
                             const std::filesystem::path& dir, const std::atomic<int>& stop,
                             const JobRunner::Report& report) {
  Progress progress;
  progress.job = job;
  auto transition = [&](JobState s, const std::string& cause) {
    journal.set_state(job, s, cause);
    progress.state = s;
    progress.event = std::string(to_string(s)) + (cause.empty() ? "" : ": " + cause);
    report(progress);
  };
  // The target stands at the table origin: its frame is the table's.
  sp::CellModel placed = models.cell;
  placed.object_on_table = Eigen::Isometry3d::Identity();
  const sp::TriangleMesh target = kind == "sensor"           ? cal::sensor_target()
                                  : kind == "turntable_axis" ? cal::spheres_target(cal::axis_sphere())
                                                             : cal::spheres_target(cal::tripod());
  try {
    transition(JobState::executing, "calibration run '" + kind + "'");
    const auto head = heads(sp::with_fixtures(target, placed), target.triangles.size(), placed);
    cal::RunContext ctx{placed, models.sensor, {}, {}, {}};
    ctx.scan = [&](const sp::JointVector& q, double length) {
      ++progress.view;
      // Calibration fits read every profile of a target: a sweep that lost some (a loaded machine misses
      // position compares) is retaken rather than fitted with a hole where a sphere was.
      const auto take = [&] {
        return acquire_view(positioner, *head, placed, models.sensor, q, length, settings, stop, [&](const std::string& what) {
          progress.event = "calibration scan " + std::to_string(progress.view) + ": " + what;
          report(progress);
        });
      };
      return take_whole(take, kCalibrationScanAttempts, kCalibrationMaxGapRows, [&](const std::string& line) {
               journal.event(job, "calibration scan " + std::to_string(progress.view) + ": " + line);
             }).image;
    };
    ctx.move = [&](const sp::JointVector& q) {
      std::map<std::string, double> t;
      for (std::size_t a = 0; a < placed.axes.size(); ++a) t[placed.axes[a].name] = q[a];
      positioner.move(t, settings.move_timeout);
    };
    ctx.log = [&](const std::string& line) {
      journal.event(job, line);
      progress.event = line;
      report(progress);
    };
    cal::CalibrationRecord record;
    if (kind == "sensor") record = cal::record_of(cal::run_sensor(ctx), placed.name);
    else if (kind == "turntable_axis") record = cal::record_of(cal::run_turntable_axis(ctx), placed.name);
    else record = cal::record_of(cal::run_positioner(ctx), placed.name);
    std::string stamp = record.date;
    stamp.erase(std::remove_if(stamp.begin(), stamp.end(), [](char c) { return c == '-' || c == ':'; }), stamp.end());
    const auto file = dir / (kind + "-" + stamp + ".yaml");
    cal::write_calibration(file, record);
    const auto changes = cal::apply_calibration(cal::load_calibration(file), models.sensor, models.cell);
    json result = {{"state", "done"}, {"kind", kind}, {"file", file.string()}, {"values", record.values},
                   {"residuals", record.residuals}, {"changes", changes}, {"scans", progress.view}};
    journal.set_result(job, result.dump());
    transition(JobState::done, "calibration " + kind + " written to " + file.string() + "; " + std::to_string(changes.size()) + " values changed");
    return JobState::done;
  } catch (const Interrupted& e) {
    positioner.halt_all();
    if (e.why == StopRequest::abort) {
      transition(JobState::aborted, std::string("by request ") + e.what());
      return JobState::aborted;
    }
    if (e.why == StopRequest::pause) {
      transition(JobState::paused, std::string(e.what()) + "; the run starts again from its first scan");
      return JobState::paused;
    }
    journal.event(job, "daemon stopping; the calibration run starts again from its first scan");
    return journal.job(job).state;
  } catch (const drivers::DriverError& e) {
    positioner.halt_all();
    progress.fault_axis = e.axis;
    progress.fault_kind = drivers::to_string(e.kind);
    transition(JobState::faulted, e.what());
    return JobState::faulted;
  } catch (const std::exception& e) {
    // Bad data (a scan without the target, a fit that does not converge): nothing is applied.
    positioner.halt_all();
    journal.set_result(job, json({{"state", "failed"}, {"kind", kind}, {"error", e.what()}}).dump());
    transition(JobState::failed, std::string(e.what()) + "; the previous calibration stays in force");
    return JobState::failed;
  }
}

}  // namespace scancell::daemon
