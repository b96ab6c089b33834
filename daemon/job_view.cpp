// One view of a round: move, sweep (with fill sweeps), register to the model (thesis 1.1.4), store durably,
// then count its coverage of the rough model.
#include "daemon/job_runner_detail.hpp"

#include <chrono>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "common/timing.hpp"
#include "daemon/acquire.hpp"
#include "planner/reconstruction/registration.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::daemon {

using nlohmann::json;
namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using namespace job_detail;

void JobRunner::note_lost_profiles(Job& j, std::int64_t plan, int view, const sp::RangeImage& img,
                                   const std::vector<std::uint32_t>& predicted) {
  auto passed = rows_passed_without_profile(img, j.rough->points, predicted);
  if (!passed.empty()) j.excused[plan][view] = std::move(passed);
}

void JobRunner::execute_view(Job& j, std::int64_t plan, const ViewRecord& v, const std::atomic<int>& stop) {
  const auto t0 = std::chrono::steady_clock::now();
  const json pj = json::parse(v.pose_json);
  const double L = pj.at("scan_length_mm").get<double>();
  const auto q = pj.at("axes").get<std::vector<double>>();
  const sp::CellModel& cell = j.cell;
  if (q.size() != cell.axes.size())
    throw scancell::DataError("plan " + std::to_string(plan) + " view " + std::to_string(v.index) + ": " + std::to_string(q.size()) +
                        " axis targets for a cell of " + std::to_string(cell.axes.size()) + " axes");

  j.progress.view = v.index + 1;
  double remaining = 0.0;
  for (std::size_t k = static_cast<std::size_t>(v.index); k < j.planned_view_s.size(); ++k) remaining += j.planned_view_s[k];
  if (j.views_timed > 0 && j.planned_view_s.size() > static_cast<std::size_t>(v.index))
    remaining = j.view_seconds * static_cast<double>(j.planned_view_s.size() - static_cast<std::size_t>(v.index));
  j.progress.eta_s = remaining;

  const Acquisition got = acquire_view(positioner_, *j.head, cell, models_.sensor, q, L, settings_, stop, [&](const std::string& what) {
    trace_.mark(what);
    j.progress.event = "view " + std::to_string(v.index + 1) + "/" + std::to_string(j.progress.views) + ": " + what;
    report_(j.progress);
  });
  sp::RangeImage img = got.image;
  const int lost = got.lost_profiles;
  if (static_cast<std::size_t>(v.index) < j.view_rows.size())
    note_lost_profiles(j, plan, v.index, img, j.view_rows[static_cast<std::size_t>(v.index)]);

  // Register the view to the model before its coverage counts (thesis 1.1.4: the positioner's pose is not
  // good enough to trust the samples where it put them).
  std::string note, registration;
  trace_.mark("registering");  // the sweep is over: from here to "stored" the view exists only in memory
  if (j.cloud) {
    // Rotations about each profile's laser origin: a camera orientation error shears a line scan. A fused
    // rough model is off by up to its voxel: what a view's shape fixes only weakly is left as positioned.
    const sp::IcpOptions icp = j.request.bbox_mm ? sp::for_model_error(settings_.icp, settings_.rough_scan.fusion.voxel_mm) : settings_.icp;
    const sp::IcpResult r = sp::register_scan(sp::scan_samples(img), *j.cloud, icp);
    if (r.ok) {
      // Against a fused rough model the correction is partly the model's own error: believe it as far as
      // the positioner is less certain than the model.
      const double weight = j.request.bbox_mm ? sp::correction_weight(cell.pose_error, models_.sensor.optimal_standoff_mm,
                                                                        settings_.fused_model_sigma_mm)
                                              : 1.0;
      sp::apply_correction(img, sp::scale_correction(r.correction, weight));
      registration = ", registered (samples moved " + fmt(r.moved_mean_mm, 3) + " mm on average, " + fmt(r.moved_max_mm, 3) +
                     " mm at most, turned " + fmt(Eigen::AngleAxisd(r.correction.linear()).angle() * 180.0 / M_PI, 3) + "°, residual " +
                     fmt(r.rms_mm, 3) + " mm" +
                     (r.free_directions ? ", " + std::to_string(r.free_directions) + " directions left as positioned" : "") +
                     (weight < 0.999 ? ", applied at " + fmt(weight, 2) + " against the rough model's own error" : "") + ")";
    } else {
      note = "registration failed: " + r.why;
      registration = ", " + note + "; not counted";
    }
  }
  // Store (durable before it counts), then update the measured coverage and the model views register to.
  trace_.mark("storing");
  img.job = j.id;
  journal_.store_scan(plan, v.index, sp::range_image_to_ply(img), note);
  trace_.mark("stored");
  if (note.empty()) {
    j.coverage->add(img);
    if (j.cloud) {
      std::vector<Eigen::Vector3d> p, n;
      sp::image_points_normals(img, 3, p, n);
      j.cloud->add(p, n);
    }
  }
  j.progress.measured = j.coverage->coverage();
  const double secs = seconds_since(t0);
  j.view_seconds = (j.view_seconds * j.views_timed + secs) / (j.views_timed + 1);
  ++j.views_timed;
  j.progress.eta_s = j.view_seconds * static_cast<double>(j.planned_view_s.size() - static_cast<std::size_t>(v.index) - 1);
  j.progress.event = "view " + std::to_string(v.index + 1) + "/" + std::to_string(j.progress.views) + " stored: " +
                     std::to_string(img.valid_count()) + " samples" + (got.fill_sweeps ? ", " + std::to_string(got.fill_sweeps) + " fill sweep" + (got.fill_sweeps > 1 ? "s" : "") + " took " +
                                                 std::to_string(got.filled_profiles) + " profiles"
                                           : "") +
                     (lost ? ", " + std::to_string(lost) + " profiles missed" +
                                 (settings_.fill_sweeps > 0 ? " after the fill sweeps (a loaded host or a lossy link: lower jobs.scan_speed_mm_s "
                                                              "or raise jobs.fill_sweeps)"
                                                            : " (jobs.fill_sweeps 0 keeps them missing)")
                            : "") +
                     registration + ", measured " + fmt(j.progress.measured) + " (" + fmt(secs, 2) + " s)";
  journal_.event(j.id, j.progress.event);
  report_(j.progress);
}

}  // namespace scancell::daemon
