#include "daemon/daemon_config.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "calibration/results.hpp"
#include "common/yaml_section.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;
namespace fs = std::filesystem;

namespace {

fs::path relative_to(const fs::path& base, const std::string& p) {
  const fs::path q(p);
  return q.is_absolute() ? q : fs::absolute(base.parent_path() / q).lexically_normal();
}

/// A file named by `key`, relative to the config file; refused naming the key when it does not exist.
fs::path existing_file(const DaemonConfig& c, scancell::Section& s, const std::string& key) {
  const fs::path p = relative_to(c.file, s.get<std::string>(key));
  if (!fs::exists(p)) s.fail(s.key_path(key), "no such file '" + p.string() + "'");
  return p;
}

/// The model files, calibration files, data directory and LCM URL at the top level.
void read_files(DaemonConfig& c, scancell::Section& y, const std::string& data_dir) {
  c.cell_file = existing_file(c, y, "cell");
  c.drivers_file = existing_file(c, y, "drivers");
  c.sensor_file = existing_file(c, y, "sensor");
  c.spec_file = existing_file(c, y, "spec");
  c.planner_file = existing_file(c, y, "planner");
  if (y.has("calibration")) {
    const YAML::Node n = y.raw("calibration");
    if (!n.IsSequence()) y.fail("calibration", "must be a list of files");
    for (std::size_t k = 0; k < n.size(); ++k) {
      const fs::path p = relative_to(c.file, n[k].as<std::string>());
      if (!fs::exists(p)) y.fail("calibration[" + std::to_string(k) + "]", "no such file '" + p.string() + "'");
      c.calibration_files.push_back(p);
    }
  }
  const std::string data_key = y.get<std::string>("data_dir");
  c.data_dir = data_dir.empty() ? relative_to(c.file, data_key) : fs::absolute(data_dir);
  c.lcm_url = y.get_or<std::string>("lcm_url", std::string("udpm://239.255.76.67:7667?ttl=0"));
  if (c.lcm_url.rfind("udpm://", 0) != 0 && c.lcm_url.rfind("memq://", 0) != 0 && c.lcm_url.rfind("file://", 0) != 0)
    y.fail("lcm_url", "must be a udpm://, memq:// or file:// LCM URL, got '" + c.lcm_url + "'");
}

void read_control(DaemonConfig& c, scancell::Section s, const std::string& socket) {
  const std::string socket_key = s.get<std::string>("socket");
  c.socket_path = socket.empty() ? relative_to(c.file, socket_key) : fs::absolute(socket);
  c.control.group = s.get_or<std::string>("group", "");
  c.control.max_clients = s.ranged<int>("max_clients", c.control.max_clients, 1, 1000);
  c.control.idle_timeout_s = s.ranged<double>("idle_timeout_s", c.control.idle_timeout_s, 0.1, 86400.0);
  c.control.send_timeout_s = s.ranged<double>("send_timeout_s", c.control.send_timeout_s, 0.1, 600.0);
  s.finish();
}

/// The GenICam driver's settings, each declared once with its range (drivers/genicam/genicam_scanner.hpp).
void read_genicam(DaemonConfig& c, scancell::Section& s) {
  auto& g = c.genicam;
  g.device = s.get_or<std::string>("device", c.scanner_driver == "sim_gige" ? "127.0.0.1" : "");
  using G = drivers::GenicamConfig;
  auto ranged = [&](const char* key, auto fallback, auto lim) { return s.ranged<decltype(fallback)>(key, fallback, lim.lo, lim.hi); };
  g.profiles_per_frame = ranged("profiles_per_frame", g.profiles_per_frame, G::profiles_per_frame_limits);
  g.trigger_line = s.get_or<std::string>("trigger_line", g.trigger_line);
  g.packet_size_bytes = s.ranged<int>("packet_size_bytes", g.packet_size_bytes, 0, G::packet_size_bytes_limits.hi);  // 0: the device's
  g.mark_columns = s.ranged<int>("mark_columns", g.mark_columns, 0, 2);
  g.mono16_scale_mm = ranged("mono16_scale_mm", g.mono16_scale_mm, G::mono16_scale_mm_limits);
  g.mono16_offset_mm = ranged("mono16_offset_mm", g.mono16_offset_mm, G::mono16_offset_mm_limits);
  g.exposure_us = ranged("exposure_us", g.exposure_us, G::exposure_us_limits);
  g.stream_buffers = ranged("stream_buffers", g.stream_buffers, G::stream_buffers_limits);
  try {
    drivers::check_genicam_config(g, "scanner");
  } catch (const drivers::DriverError& e) {
    s.fail(e.where, e.cause);  // e.where is the key path (scanner.device, ...)
  }
}

/// The simulated cell's truth where it differs from the models: what calibration must recover.
SimTruth read_truth(const DaemonConfig& c, scancell::Section t) {
  SimTruth truth;
  if (t.has("sensor")) truth.sensor = sp::load_sensor(existing_file(c, t, "sensor"));
  if (t.has("table_axis")) {
    scancell::Section a = t.section("table_axis");
    truth.table_axis_point_mm = a.vec3("point_mm");
    truth.table_axis_direction = a.vec3("direction");
    if (!(truth.table_axis_direction.norm() > 0.0)) a.fail(a.key_path("direction"), "must not be zero");
    truth.table_axis_direction.normalize();
    a.finish();
  }
  if (t.has("pose_error")) {
    scancell::Section p = t.section("pose_error");
    truth.pose_error.sigma_p_mm = p.non_negative("sigma_p_mm", 0.0);
    truth.pose_error.sigma_a_rad = p.non_negative("sigma_a_rad", 0.0);
    truth.pose_error.sigma_t_rad = p.non_negative("sigma_t_rad", 0.0);
    p.finish();
  }
  truth.seed = t.get_or<std::uint64_t>("seed", 1);
  t.finish();
  return truth;
}

void read_scanner(DaemonConfig& c, scancell::Section s) {
  c.scanner_driver = s.get<std::string>("driver");
  if (c.scanner_driver != "sim" && c.scanner_driver != "sim_gige" && c.scanner_driver != "genicam")
    s.fail(s.key_path("driver"), "must be sim, sim_gige or genicam, got '" + c.scanner_driver + "'");
  c.scanner_seed = s.get_or<std::uint64_t>("seed", 1);
  const std::string source = s.get_or<std::string>("trigger_source", "daemon");
  if (source != "daemon" && source != "drive_compare")
    s.fail(s.key_path("trigger_source"), "must be daemon or drive_compare, got '" + source + "'");
  c.jobs.drive_compare = source == "drive_compare";
  if (c.scanner_driver != "sim") read_genicam(c, s);
  if (c.scanner_driver == "genicam") {
    scancell::Section t = s.section("trigger");
    c.trigger_chip = t.get<std::string>("chip");
    c.trigger_offset = static_cast<unsigned>(t.ranged<int>("offset", 0, 0, 1023));
    t.finish();
  }
  if (c.scanner_driver == "genicam" && c.trigger_chip == "sim" && !c.jobs.drive_compare)
    s.fail(s.key_path("trigger") + ".chip", "sim is no line a real scanner can see: give the GPIO chip of its trigger input, or set "
                                            "scanner.trigger_source: drive_compare (the sweep drive's compare output triggers it)");
  if (c.scanner_driver == "genicam" && s.has("truth"))
    s.fail(s.key_path("truth"), "a simulated cell's truth with a real scanner (driver genicam)");
  if (s.has("truth")) c.truth = read_truth(c, s.section("truth"));
  s.finish();
}

/// Bounding-box jobs: the exploration program and the fusion of its images (docs/rough-scan.md).
void read_rough_scan(DaemonConfig& c, scancell::Section s) {
  auto& r = c.jobs.rough_scan;
  r.table_steps = s.ranged("table_steps", r.table_steps, 3, 72);
  if (s.has("tilts_rad")) {
    r.tilts_rad.clear();
    const YAML::Node n = s.raw("tilts_rad");
    if (!n.IsSequence() || n.size() == 0) s.fail(s.key_path("tilts_rad"), "must be a list of camera tilts, rad");
    for (std::size_t k = 0; k < n.size(); ++k) {
      double t = 0.0;
      try {
        t = n[k].as<double>();
      } catch (const YAML::Exception&) {
        s.fail(s.key_path("tilts_rad") + "[" + std::to_string(k) + "]", "cannot read it as a number");
      }
      if (!(std::abs(t) < 1.5)) s.fail(s.key_path("tilts_rad") + "[" + std::to_string(k) + "]", "must be within ±1.5 rad");
      r.tilts_rad.push_back(t);
    }
  }
  r.fusion.voxel_mm = s.ranged("voxel_mm", r.fusion.voxel_mm, 0.25, 10.0);
  r.fusion.truncation_voxels = s.ranged("truncation_voxels", r.fusion.truncation_voxels, 1.0, 10.0);
  r.fusion.occluding_views = s.ranged("occluding_views", r.fusion.occluding_views, 1, 1000);
  s.finish();
}

/// The only directories a client's submit may name files in (mesh, truth, spec, settings); resolved now,
/// links included, so a client's path is compared with what it really is.
void read_allowed_dirs(DaemonConfig& c, scancell::Section& s) {
  const YAML::Node n = s.raw("allowed_dirs");
  if (!n.IsSequence() || n.size() == 0) s.fail(s.key_path("allowed_dirs"), "must be a non-empty list of directories");
  for (std::size_t k = 0; k < n.size(); ++k) {
    const std::string at = s.key_path("allowed_dirs") + "[" + std::to_string(k) + "]";
    if (!n[k].IsScalar()) s.fail(at, "must be a directory path");
    const fs::path d = relative_to(c.file, n[k].as<std::string>());
    std::error_code ec;
    if (!fs::is_directory(d, ec)) s.fail(at, "'" + d.string() + "' is not a directory");
    c.allowed_dirs.push_back(fs::canonical(d));
  }
}

/// jobs: the 3M loop's limits, setups, execution and the daemon's own timeouts, each with its range.
void read_jobs(DaemonConfig& c, scancell::Section s) {
  auto& j = c.jobs;
  j.max_rounds = s.ranged("max_rounds", j.max_rounds, 1, 50);
  j.retire_after_failures = s.ranged("retire_after_failures", j.retire_after_failures, 1, 10);
  j.failed_row_weight = s.ranged("failed_row_weight", j.failed_row_weight, 0.0, 1.0);
  j.min_gain_per_view_mm2 = s.ranged("min_gain_per_view_mm2", j.min_gain_per_view_mm2, 0.0, 1e6);
  j.footprint_samples = s.ranged("footprint_samples", j.footprint_samples, 0, 64);
  j.next_setup_min_area_mm2 = s.ranged("next_setup_min_area_mm2", j.next_setup_min_area_mm2, 0.0, 1e6);
  j.max_setups = s.ranged("max_setups", j.max_setups, 1, kMaxSetups);
  j.sim_placement_error_mm = s.ranged("sim_placement_error_mm", j.sim_placement_error_mm, 0.0, 50.0);
  j.sim_placement_error_rad = s.ranged("sim_placement_error_rad", j.sim_placement_error_rad, 0.0, M_PI);
  j.coverage.row_fraction = s.positive_up_to("row_fraction", j.coverage.row_fraction, 1.0);
  j.coverage.normal_tolerance_mm = s.non_negative("normal_tolerance_mm", 0.0);
  j.move_timeout = std::chrono::milliseconds(std::lround(1000.0 * s.positive_up_to("move_timeout_s", 60.0, 3600.0)));
  j.scan_speed_mm_s = s.ranged("scan_speed_mm_s", 0.0, 0.0, 10000.0);
  j.trigger_width = std::chrono::microseconds(std::lround(s.ranged("trigger_width_us", 0.0, 0.0, 1e6)));
  j.fill_sweeps = s.ranged("fill_sweeps", j.fill_sweeps, 0, 5);
  j.cloud_spacing_mm = s.ranged("cloud_spacing_mm", j.cloud_spacing_mm, 0.0, 10.0);
  j.register_views = s.get_or<bool>("register_views", j.register_views);
  j.fused_model_sigma_mm = s.ranged("fused_model_sigma_mm", j.fused_model_sigma_mm, 0.0, 10.0);
  j.planner_threads = s.ranged("planner_threads", 0, 0, 1024);  // 0: all cores
  c.home_timeout = std::chrono::milliseconds(std::lround(1000.0 * s.positive_up_to("home_timeout_s", 60.0, 3600.0)));
  if (s.has("phase_trace_file")) j.phase_trace_file = relative_to(c.file, s.get<std::string>("phase_trace_file"));
  s.declare("phase_trace_file", "none", "");  // optional, no default: the trace is off unless a file is named
  if (s.has("allowed_dirs")) read_allowed_dirs(c, s);
  s.finish();
}

}  // namespace

DaemonConfig load_daemon_config(const fs::path& file, const std::string& data_dir, const std::string& socket,
                                KeyDeclarations* declared) {
  DaemonConfig c;
  c.file = fs::absolute(file);
  YAML::Node holder;
  scancell::Section y = scancell::open_root(c.file, holder, declared);
  read_files(c, y, data_dir);
  read_control(c, y.section("control"), socket);
  read_scanner(c, y.section("scanner"));
  if (y.has("rough_scan")) read_rough_scan(c, y.section("rough_scan"));
  if (y.has("jobs")) read_jobs(c, y.section("jobs"));
  y.finish();
  c.jobs.jobs_dir = c.data_dir / "jobs";
  c.models.cell = sp::load_cell(c.cell_file);
  c.models.sensor = sp::load_sensor(c.sensor_file);
  c.models.spec = sp::load_spec(c.spec_file);
  c.models.settings = sp::load_planner_settings(c.planner_file);
  c.drivers = drivers::load_driver_setup(c.drivers_file);
  if (const auto sweep_drive = c.drivers.axes.find("sweep");
      c.jobs.drive_compare && sweep_drive != c.drivers.axes.end() && std::holds_alternative<drivers::CanOpenAxisConfig>(sweep_drive->second))
    y.fail("scanner.trigger_source",
           "drive_compare needs a sweep drive with a position-compare output (the Modbus map's registers 12-19); axes.sweep in " +
               c.drivers_file.string() + " is canopen: use daemon");
  bool sweep = false;
  for (const auto& a : c.models.cell.axes) sweep = sweep || a.name == "sweep";
  if (!sweep) y.fail("cell", "cell '" + c.models.cell.name + "' has no 'sweep' axis; line-scan execution needs one");
  apply_calibrations(c, c.models.sensor, c.models.cell);
  return c;
}

void apply_calibrations(DaemonConfig& c, sp::SensorModel& sensor, sp::CellModel& cell) {
  std::vector<fs::path> files = c.calibration_files;
  for (const auto& f : calibration::latest_calibrations(c.data_dir / "calibration")) files.push_back(f);
  c.calibration_applied.clear();
  for (const auto& f : files) {
    calibration::apply_calibration(calibration::load_calibration(f), sensor, cell);
    c.calibration_applied.push_back(f.string());
  }
}

std::vector<std::string> reload_calibration(DaemonConfig& c) {
  // Load everything first: a bad file leaves the running models untouched.
  sp::SensorModel sensor = sp::load_sensor(c.sensor_file);
  sp::CellModel cell = sp::load_cell(c.cell_file);
  DaemonConfig trial = c;
  apply_calibrations(trial, sensor, cell);
  std::vector<std::string> changes;
  auto differ = [](const std::string& a, const std::string& b) { return a != b; };
  std::ostringstream before, after;
  before << c.models.sensor.noise_cz_per_mm << ' ' << c.models.sensor.grazing_xz_rad << ' ' << c.models.sensor.grazing_yz_rad;
  after << sensor.noise_cz_per_mm << ' ' << sensor.grazing_xz_rad << ' ' << sensor.grazing_yz_rad;
  if (differ(before.str(), after.str()))
    changes.push_back("sensor " + c.sensor_file.string() + ": C_z t_xz t_yz " + before.str() + " -> " + after.str());
  std::ostringstream pb, pa;
  pb << c.models.cell.pose_error.sigma_p_mm << ' ' << c.models.cell.pose_error.sigma_a_rad << ' ' << c.models.cell.pose_error.sigma_t_rad;
  pa << cell.pose_error.sigma_p_mm << ' ' << cell.pose_error.sigma_a_rad << ' ' << cell.pose_error.sigma_t_rad;
  if (differ(pb.str(), pa.str()))
    changes.push_back("cell " + c.cell_file.string() + ": pose error sigma_p_mm sigma_a_rad sigma_t_rad " + pb.str() + " -> " + pa.str());
  for (const auto& f : c.calibration_files)
    if (!fs::exists(f)) throw scancell::ConfigError(f.string() + ": calibration file vanished");
  if (cell.axes.size() != c.models.cell.axes.size())
    throw scancell::ConfigError(c.cell_file.string() + ": axes changed; restart the daemon to change the cell's axes");
  if ((cell.table_axis_point_mm - c.models.cell.table_axis_point_mm).norm() > 0.0 ||
      (cell.table_axis_direction - c.models.cell.table_axis_direction).norm() > 0.0)
    changes.push_back("cell " + c.cell_file.string() + ": turntable axis changed");
  c.models.sensor = sensor;
  c.models.cell = cell;
  c.calibration_applied = trial.calibration_applied;
  return changes;
}

}  // namespace scancell::daemon
