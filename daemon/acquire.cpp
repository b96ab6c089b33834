#include "daemon/acquire.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <thread>

#include "planner/kinematics/cell.hpp"
#include "common/errors.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;
namespace dr = scancell::drivers;
using Clock = std::chrono::steady_clock;

namespace {

/// A trigger pulse fired during a sweep: the row it was for and the camera pose at the position read back.
struct Fired {
  int row;
  Eigen::Isometry3d pose;
};

/// The sweep axis' move to `end` at `speed`, read every `every` until in position, a drive fault, the deadline
/// or a stop request (the axis halted, Interrupted thrown); `poll` sees every state read, and one more after
/// finish_move (which reports a fault, or times out with a halt).
void sweep_move(dr::Positioner& positioner, double end, double speed, std::chrono::milliseconds timeout, const std::atomic<int>& stop,
                std::chrono::microseconds every, const std::function<void(const dr::AxisState&)>& poll) {
  dr::Axis& sweep_axis = positioner.axis("sweep");
  positioner.begin_move("sweep", end, speed);
  const auto deadline = Clock::now() + timeout;
  while (true) {
    const auto why = static_cast<StopRequest>(stop.load());
    if (why != StopRequest::none) {
      sweep_axis.halt();
      throw Interrupted(why, "during a sweep (its partial scan is discarded)");
    }
    const dr::AxisState st = sweep_axis.state();
    if (st.faulted) break;  // finish_move reports the drive's fault
    poll(st);
    if ((!st.moving && st.in_position) || Clock::now() > deadline) break;  // finish_move times out with a halt
    std::this_thread::sleep_for(every);
  }
  sweep_axis.finish_move(end, std::chrono::milliseconds(std::max<long>(100, std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count())));
  poll(sweep_axis.state());
}

/// One pass of the sweep from where the sweep axis stands to `end` at `speed`, firing one pulse each time it
/// passes the position of a row `wanted` marks (row r at `start` + r `pitch`) (software position compare, as a drive's
/// position-compare output would in hardware). Rows passed between two reads of the position get no pulse.
std::vector<Fired> sweep_pass(dr::Positioner& positioner, ScanHead& head, const sp::CellModel& cell, std::vector<double> qs,
                              double start, double end, double pitch, const std::vector<std::uint8_t>& wanted,
                              double speed, std::chrono::milliseconds timeout, const JobSettings& settings,
                              const std::atomic<int>& stop) {
  const std::size_t sweep = cell.axis_index("sweep");
  const int n_rows = static_cast<int>(wanted.size());
  dr::Axis& sweep_axis = positioner.axis("sweep");
  std::vector<Fired> fired;
  int next = 0;
  auto fire_up_to = [&](double y) {
    // Positions come back in drive counts (1 µm): a profile is due within half a count of its place.
    constexpr double kCount = 5e-4;
    if (next >= n_rows || y < start + next * pitch - kCount) return;
    // Rows passed since the last read are lost; fire for the latest one only, at the position read.
    const int row = std::min(n_rows - 1, static_cast<int>(std::floor((y - start + kCount) / pitch)));
    next = row + 1;
    if (!wanted[static_cast<std::size_t>(row)]) return;
    qs[sweep] = y;
    const Eigen::Isometry3d pose = sp::forward_kinematics(cell, qs);
    head.camera_at(qs, pose);
    head.trigger().set(true);
    if (settings.trigger_width.count() > 0) std::this_thread::sleep_for(settings.trigger_width);
    head.trigger().set(false);
    fired.push_back({row, pose});
  };
  fire_up_to(sweep_axis.state().position);
  sweep_move(positioner, end, speed, timeout, stop, std::chrono::microseconds(50), [&](const dr::AxisState& st) { fire_up_to(st.position); });
  return fired;
}

/// One pass of the sweep with the drive's position compare triggering the scanner (scanner.trigger_source:
/// drive_compare): armed for rows `first` … `first` + `rows` − 1 (row r at `start` + r `pitch`), then the move
/// to `end` at `speed`; each pulse the drive reports is a profile whose pose is the kinematics at its compare
/// position, not at a position read back. Rows the move did not reach (a halt, a fault) get no pulse.
std::vector<Fired> compare_pass(dr::Positioner& positioner, ScanHead& head, const sp::CellModel& cell, std::vector<double> qs,
                                double start, int first, int rows, double end, double pitch, double speed,
                                std::chrono::milliseconds timeout, const std::atomic<int>& stop) {
  const std::size_t sweep = cell.axis_index("sweep");
  dr::Axis& sweep_axis = positioner.axis("sweep");
  std::vector<Fired> fired;
  auto take_up_to = [&](int pulses) {
    for (int k = static_cast<int>(fired.size()); k < std::min(pulses, rows); ++k) {
      qs[sweep] = start + (first + k) * pitch;
      const Eigen::Isometry3d pose = sp::forward_kinematics(cell, qs);
      head.compare_pulse(qs, pose);
      fired.push_back({first + k, pose});
    }
  };
  sweep_axis.arm_position_compare(start + first * pitch, pitch, rows);
  take_up_to(sweep_axis.position_compare_fired());
  sweep_move(positioner, end, speed, timeout, stop, std::chrono::microseconds(200),
             [&](const dr::AxisState&) { take_up_to(sweep_axis.position_compare_fired()); });
  return fired;
}

/// Reads the profiles answering `fired` into `img` (object frame from each pulse's pose, view frame from the
/// image's nominal pose); returns how many arrived. Profiles are matched to rows by their pulse number, not
/// by arrival: profile base + k answers the k-th pulse of this pass. A late profile of an earlier pass is
/// skipped; one lost on the wire leaves its row unacquired, in its place.
int collect_profiles(ScanHead& head, const std::vector<Fired>& fired, int n_cols, sp::RangeImage& img) {
  const Eigen::Isometry3d object_to_view = img.pose.camera_to_object.inverse();
  const std::uint64_t base = head.pulses;
  head.pulses += fired.size();
  int delivered = 0;
  for (std::size_t expect = 0; expect < fired.size();) {
    dr::Profile prof;
    try {
      prof = head.scanner().acquire(std::chrono::milliseconds(2000));
    } catch (const dr::DriverError& e) {
      // The pass's last frame lost on the wire leaves no later frame to count its profiles: what arrived
      // stands and the rest are lost profiles. Nothing at all from a pass is a fault (trigger, cable).
      if (e.kind != dr::DriverError::Kind::timeout || expect == 0) throw;
      break;
    }
    if (prof.index < base) continue;
    const std::size_t k = static_cast<std::size_t>(prof.index - base);
    if (k >= fired.size() || k < expect)
      throw dr::DriverError(dr::DriverError::Kind::protocol, "scanner", "profile " + std::to_string(prof.index),
                            "out of order: this sweep fired pulses " + std::to_string(base) + " to " +
                                std::to_string(base + fired.size() - 1) + ", the next expected is " + std::to_string(base + expect));
    expect = k + 1;
    if (prof.lost) continue;
    const int row = fired[k].row;
    img.acquired_rows[static_cast<std::size_t>(row)] = 1;
    ++delivered;
    if (prof.samples.size() != static_cast<std::size_t>(n_cols))
      throw dr::DriverError(dr::DriverError::Kind::protocol, "scanner", "profile " + std::to_string(prof.index),
                            std::to_string(prof.samples.size()) + " samples, the sensor model has " + std::to_string(n_cols));
    for (int i = 0; i < n_cols; ++i) {
      sp::RangeSample s = prof.samples[static_cast<std::size_t>(i)];
      if (!s.valid()) continue;
      // The scanner reports points in its own frame; where they are on the object is what the cell model
      // says the camera's pose was (the position read back at the trigger): a model error shows up here.
      s.object_mm = (fired[k].pose * s.camera_mm.cast<double>()).cast<float>();
      s.camera_mm = (object_to_view * s.object_mm.cast<double>()).cast<float>();
      const std::size_t at = static_cast<std::size_t>(row) * n_cols + i;
      img.samples[at] = s;
      if (!prof.truth.empty()) {
        if (img.truth.empty()) img.truth.assign(img.samples.size(), sp::SampleTruth{});
        img.truth[at] = prof.truth[static_cast<std::size_t>(i)];
      }
    }
  }
  return delivered;
}

}  // namespace

Acquisition acquire_view(dr::Positioner& positioner, ScanHead& head, const sp::CellModel& cell,
                         const sp::SensorModel& sensor, const sp::JointVector& q, double L, const JobSettings& settings,
                         const std::atomic<int>& stop, const std::function<void(const std::string&)>& phase) {
  if (q.size() != cell.axes.size())
    throw scancell::DataError(std::to_string(q.size()) + " axis targets for a cell of " + std::to_string(cell.axes.size()) + " axes");
  const std::size_t sweep = cell.axis_index("sweep");
  const double mid = q[sweep], start = mid - 0.5 * L, end = mid + 0.5 * L;
  const int n_rows = sensor.samples_y, n_cols = sensor.samples_x;
  if (phase) phase("moving");
  // 1. Move to the start of the sweep, every axis together.
  std::map<std::string, double> targets;
  for (std::size_t a = 0; a < cell.axes.size(); ++a) targets[cell.axes[a].name] = a == sweep ? start : q[a];
  positioner.move(targets, settings.move_timeout);
  head.moved();

  // 2. The range image of the view (the nominal pose at mid-sweep; samples carry their own measured
  //    positions in both frames), filled by the sweep's profiles. The pose of each profile is the kinematics
  //    at the position read back: what the camera really did, not what was planned.
  sp::RangeImage img;
  img.kind = sensor.kind;
  img.columns = n_cols;
  img.rows = n_rows;
  std::vector<double> qs = q;
  qs[sweep] = mid;
  img.pose.camera_to_object = sp::forward_kinematics(cell, qs);
  img.pose.scan_length_mm = L;
  img.samples.assign(static_cast<std::size_t>(n_cols) * n_rows, sp::RangeSample{});
  img.acquired_rows.assign(static_cast<std::size_t>(n_rows), 0);

  const double speed = settings.scan_speed_mm_s > 0.0 ? settings.scan_speed_mm_s : cell.scan_speed_mm_s;
  const double pitch = L / (n_rows - 1);
  const auto sweep_timeout = std::chrono::milliseconds(static_cast<long>(2000.0 * L / speed)) + settings.move_timeout;
  if (phase) phase("scanning");
  const std::vector<std::uint8_t> all(static_cast<std::size_t>(n_rows), 1);
  collect_profiles(head,
                   settings.drive_compare ? compare_pass(positioner, head, cell, q, start, 0, n_rows, end, pitch, speed, sweep_timeout, stop)
                                          : sweep_pass(positioner, head, cell, q, start, end, pitch, all, speed, sweep_timeout, settings, stop),
                   n_cols, img);
  auto acquired = [&img] { return static_cast<int>(std::count(img.acquired_rows.begin(), img.acquired_rows.end(), 1)); };
  int delivered = acquired();

  // 3. Fill sweeps: the rows the sweep passed without a profile are swept again, the sweep axis alone back to
  //    the first of them (the other axes stay: the camera's pose is the same positioning), firing only at them.
  //    A lost profile is a missed position compare or frame, not a property of the surface: nothing is left
  //    missing that one more pass can take (a loaded host misses single profiles at high sweep speeds). Each
  //    pass goes at half the speed of the one before: a host too slow to read the position once per profile
  //    at one speed reads it twice as often per profile at half of it.
  Acquisition out;
  double fill_speed = speed;
  for (int fill = 1; fill <= settings.fill_sweeps && delivered < n_rows; ++fill) {
    fill_speed *= 0.5;
    std::vector<std::uint8_t> missing(static_cast<std::size_t>(n_rows));
    int first = n_rows, last = -1;
    for (int r = 0; r < n_rows; ++r) {
      missing[static_cast<std::size_t>(r)] = !img.acquired_rows[static_cast<std::size_t>(r)];
      if (missing[static_cast<std::size_t>(r)]) first = std::min(first, r), last = r;
    }
    // Over the missing rows' span only, from half a pitch before the first (so it is passed, not started on).
    const double from = std::max(start, start + (first - 0.5) * pitch), to = std::min(end, start + (last + 0.5) * pitch);
    if (phase) phase("moving");
    positioner.move({{cell.axes[sweep].name, from}}, settings.move_timeout);
    if (phase) phase("scanning");
    const auto timeout = std::chrono::milliseconds(static_cast<long>(2000.0 * (to - from) / fill_speed)) + settings.move_timeout;
    // With the drive's compare, every row of the span is taken again (acquired ones are replaced by profiles
    // as good); the daemon's own compare fires at the missing rows only.
    collect_profiles(
        head,
        settings.drive_compare ? compare_pass(positioner, head, cell, q, start, first, last - first + 1, to, pitch, fill_speed, timeout, stop)
                               : sweep_pass(positioner, head, cell, q, start, to, pitch, missing, fill_speed, timeout, settings, stop),
        n_cols, img);
    const int got = acquired() - delivered;  // rows taken for the first time
    out.filled_profiles += got;
    delivered += got;
    out.fill_sweeps = fill;
  }
  out.lost_profiles = n_rows - delivered;
  out.image = std::move(img);
  return out;
}

int longest_lost_run(const sp::RangeImage& image) {
  int run = 0, longest = 0;
  for (const std::uint8_t acquired : image.acquired_rows) {
    run = acquired ? 0 : run + 1;
    longest = std::max(longest, run);
  }
  return longest;
}

std::vector<std::uint32_t> rows_passed_without_profile(const sp::RangeImage& image, const std::vector<Eigen::Vector3d>& points,
                                                       const std::vector<std::uint32_t>& rows) {
  const int n = image.rows;
  if (image.acquired_rows.empty() || rows.empty() || n < 2) return {};
  if (image.acquired_rows.size() != static_cast<std::size_t>(n))
    throw scancell::DataError("range image: " + std::to_string(image.acquired_rows.size()) + " acquired-row flags for " +
                        std::to_string(n) + " rows");
  for (const auto r : rows)
    if (r >= points.size()) throw scancell::DataError("row " + std::to_string(r) + " of " + std::to_string(points.size()) + " rough-model points");
  if (longest_lost_run(image) == 0) return {};
  // Least-squares line y = a + b j through each acquired row's mean view-frame y.
  double s1 = 0, sj = 0, sy = 0, sjj = 0, sjy = 0;
  for (int j = 0; j < n; ++j) {
    if (!image.acquired_rows[static_cast<std::size_t>(j)]) continue;
    double y = 0;
    int k = 0;
    for (int i = 0; i < image.columns; ++i)
      if (image.at(i, j).valid()) {
        y += image.at(i, j).camera_mm.y();
        ++k;
      }
    if (k == 0) continue;
    y /= k;
    s1 += 1;
    sj += j;
    sy += y;
    sjj += double(j) * j;
    sjy += j * y;
  }
  const double det = s1 * sjj - sj * sj;
  if (s1 < 2 || std::abs(det) < 1e-12) return rows;
  const double b = (s1 * sjy - sj * sy) / det, a = (sy - b * sj) / s1;
  if (std::abs(b) < 1e-9) return rows;
  const Eigen::Isometry3d object_to_view = image.pose.camera_to_object.inverse();
  std::vector<std::uint32_t> out;
  for (const auto r : rows) {
    const double j = ((object_to_view * points[r]).y() - a) / b;
    if (j < -1.0 || j > n) continue;  // outside the sweep: a lost profile cannot be why
    const int lo = std::max(0, static_cast<int>(std::floor(j)) - 1), hi = std::min(n - 1, static_cast<int>(std::ceil(j)) + 1);
    for (int k = lo; k <= hi; ++k)
      if (!image.acquired_rows[static_cast<std::size_t>(k)]) {
        out.push_back(r);
        break;
      }
  }
  return out;
}

Acquisition take_whole(const std::function<Acquisition()>& take, int attempts, int max_gap_rows,
                       const std::function<void(const std::string&)>& log) {
  if (attempts < 1) throw scancell::DataError("take_whole: attempts " + std::to_string(attempts) + " (at least 1)");
  Acquisition best = take();
  int gap = longest_lost_run(best.image);
  for (int a = 2; a <= attempts && gap > max_gap_rows; ++a) {
    if (log)
      log(std::to_string(gap) + " profiles in a row lost in the sweep (" + std::to_string(best.lost_profiles) + " of " +
          std::to_string(best.image.rows) + " in all); taking it again (attempt " + std::to_string(a) + " of " + std::to_string(attempts) + ")");
    Acquisition next = take();
    const int next_gap = longest_lost_run(next.image);
    if (next_gap < gap) {
      best = std::move(next);
      gap = next_gap;
    }
  }
  return best;
}

}  // namespace scancell::daemon
