#include "planner/config.hpp"

#include <cmath>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "common/yaml_section.hpp"

#include "planner/kinematics/arm_ik.hpp"
#include "planner/kinematics/cell.hpp"
#include "common/errors.hpp"

namespace scancell::planner {
const char* to_string(SensorKind k) { return k == SensorKind::line_scan ? "line_scan" : "random_access"; }
const char* to_string(ViewpointScheme s) { return s == ViewpointScheme::variable ? "variable" : "decoupled"; }
const char* to_string(CoverMode m) {
  return m == CoverMode::greedy ? "greedy" : m == CoverMode::constrained ? "constrained" : "exact";
}
const char* to_string(RegistrationNormalizer n) { return n == RegistrationNormalizer::max_view ? "max_view" : "smaller_view"; }

void validate(const SensorModel& s, const std::string& w) {
  auto bad = [&](const std::string& key, const std::string& why) { throw ConfigError(w + ": " + key + ": " + why); };
  if (!(s.fov_x_rad > 0.0 && s.fov_x_rad < 3.0)) bad("fov_x_rad", "must be in (0, 3)");
  if (s.kind == SensorKind::random_access && !(s.fov_y_rad > 0.0 && s.fov_y_rad < 3.0)) bad("fov_y_rad", "must be in (0, 3)");
  if (!(s.range_min_mm > 0.0)) bad("range_min_mm", "must be > 0");
  if (!(s.range_min_mm < s.range_max_mm)) bad("range_max_mm", "must be greater than range_min_mm");
  if (!(s.optimal_standoff_mm >= s.range_min_mm && s.optimal_standoff_mm <= s.range_max_mm))
    bad("optimal_standoff_mm", "must lie within [range_min_mm, range_max_mm]");
  if (!(s.baseline_mm > 0.0)) bad("baseline_mm", "must be > 0");
  if (s.samples_x < 2) bad("samples_x", "must be >= 2");
  if (s.samples_y < 2) bad("samples_y", "must be >= 2");
  if (s.kind == SensorKind::line_scan) {
    if (!(s.scan_length_min_mm > 0.0)) bad("scan_length_min_mm", "must be > 0");
    if (!(s.scan_length_min_mm <= s.scan_length_max_mm)) bad("scan_length_max_mm", "must be >= scan_length_min_mm");
  }
  if (!(s.noise_cz_per_mm > 0.0)) bad("noise.cz_per_mm", "must be > 0");
  if (!(s.noise_cx >= 0.0)) bad("noise.cx", "must be >= 0");
  if (!(s.noise_cy >= 0.0)) bad("noise.cy", "must be >= 0");
  if (!(s.grazing_xz_rad > 0.0 && s.grazing_xz_rad <= 1.5707963267948966)) bad("grazing.t_xz_rad", "must be in (0, pi/2]");
  if (!(s.grazing_yz_rad > 0.0 && s.grazing_yz_rad <= 1.5707963267948966)) bad("grazing.t_yz_rad", "must be in (0, pi/2]");
}

void validate(const ModelSpec& s, const std::string& w) {
  auto bad = [&](const std::string& key, const std::string& why) { throw ConfigError(w + ": " + key + ": " + why); };
  if (!(s.precision_mm > 0.0)) bad("precision_mm", "must be > 0");
  if (!(s.density_per_mm2 > 0.0)) bad("density_per_mm2", "must be > 0");
  if (!(s.coverage_goal > 0.0 && s.coverage_goal <= 1.0)) bad("coverage_goal", "must be in (0, 1]");
}

namespace {

SensorModel sensor_from(Section& y, const std::string& where, const std::string& default_name) {
  SensorModel s;
  s.name = y.get_or<std::string>("name", default_name);
  const std::string kind = y.get<std::string>("kind");
  if (kind == "line_scan") s.kind = SensorKind::line_scan;
  else if (kind == "random_access") s.kind = SensorKind::random_access;
  else y.fail("kind", "must be line_scan or random_access, got '" + kind + "'");
  s.fov_x_rad = y.positive("fov_x_rad");
  if (s.kind == SensorKind::random_access) s.fov_y_rad = y.positive("fov_y_rad");
  else s.fov_y_rad = y.non_negative("fov_y_rad", 0.0);  // plan files carry it for every kind; unused here
  s.range_min_mm = y.positive("range_min_mm");
  s.range_max_mm = y.positive("range_max_mm");
  if (!(s.range_min_mm < s.range_max_mm)) y.fail("range_max_mm", "must be greater than range_min_mm");
  s.optimal_standoff_mm = y.get_or<double>("optimal_standoff_mm", s.range_min_mm);
  s.baseline_mm = y.positive("baseline_mm");
  if (s.kind == SensorKind::line_scan) {
    s.scan_length_min_mm = y.positive("scan_length_min_mm");
    s.scan_length_max_mm = y.positive("scan_length_max_mm");
  } else {
    s.scan_length_min_mm = y.non_negative("scan_length_min_mm", 0.0);
    s.scan_length_max_mm = y.non_negative("scan_length_max_mm", 0.0);
  }
  s.samples_x = y.get<int>("samples_x");
  s.samples_y = y.get<int>("samples_y");
  {
    Section n = y.section("noise");
    s.noise_cx = n.non_negative("cx", 0.0);
    s.noise_cy = n.non_negative("cy", 0.0);
    s.noise_cz_per_mm = n.positive("cz_per_mm");
    n.finish();
  }
  {
    Section g = y.section("grazing");
    s.grazing_xz_rad = g.positive("t_xz_rad");
    s.grazing_yz_rad = g.positive("t_yz_rad");
    g.finish();
  }
  y.finish();
  validate(s, where);
  return s;
}

ModelSpec spec_from(Section& y, const std::string& where, const std::string& default_name) {
  ModelSpec s;
  s.name = y.get_or<std::string>("name", default_name);
  s.precision_mm = y.positive("precision_mm");
  s.density_per_mm2 = y.positive("density_per_mm2");
  s.coverage_goal = y.get_or<double>("coverage_goal", 1.0);
  y.finish();
  validate(s, where);
  return s;
}

}  // namespace

SensorModel load_sensor(const std::filesystem::path& file, KeyDeclarations* declared) {
  YAML::Node root;
  Section y = open_root(file, root, declared);
  return sensor_from(y, file.string(), file.stem().string());
}

SensorModel parse_sensor(const std::string& text, const std::string& where) {
  YAML::Node root;
  Section y = parse_root(text, where, root);
  return sensor_from(y, where, "sensor");
}

ModelSpec parse_spec(const std::string& text, const std::string& where) {
  YAML::Node root;
  Section y = parse_root(text, where, root);
  return spec_from(y, where, "spec");
}

ModelSpec load_spec(const std::filesystem::path& file) {
  YAML::Node root;
  Section y = open_root(file, root);
  return spec_from(y, file.string(), file.stem().string());
}

namespace {

/// The detuned tests' margins (thesis 7.4.7) from a mapping: every key optional, none negative.
Countermeasures parse_countermeasures(Section k) {
  Countermeasures cm;
  cm.frustum_detune = k.ranged_below("frustum_detune", 0.0, 0.0, 0.9);
  cm.dof_margin_mm = k.non_negative("dof_margin_mm", 0.0);
  cm.compliance_buffer = k.non_negative("compliance_buffer", 0.0);
  cm.visibility_margin_mm = k.non_negative("visibility_margin_mm", 0.0);
  k.finish();
  return cm;
}

}  // namespace

namespace {

/// A count given as a YAML number (1e9 reads as a double): whole, within [lo, hi].
std::uint64_t whole_number(Section& s, const std::string& key, std::uint64_t fallback, double lo, double hi) {
  const double v = s.get_or<double>(key, static_cast<double>(fallback));
  s.declare(key, Section::text_of(fallback), "[" + Section::text_of(lo) + ", " + Section::text_of(hi) + "]");
  if (!s.has(key)) return fallback;
  if (!(v >= lo && v <= hi && v == std::floor(v))) {
    std::ostringstream os;
    os << "must be a whole number in [" << lo << ", " << hi << "], got " << v;
    s.fail(s.key_path(key), os.str());
  }
  return static_cast<std::uint64_t>(v);
}

void read_viewpoints(Section v, ViewpointSettings& vs) {
  const std::string scheme = v.get_or<std::string>("scheme", to_string(vs.scheme));
  if (scheme == "variable") vs.scheme = ViewpointScheme::variable;
  else if (scheme == "decoupled") vs.scheme = ViewpointScheme::decoupled;
  else v.fail(v.key_path("scheme"), "must be variable or decoupled, got '" + scheme + "'");
  vs.standoff_factor = v.ranged("standoff_factor", vs.standoff_factor, 1.0, 2.0);
  vs.position_decimation = v.ranged("position_decimation", vs.position_decimation, 1, std::numeric_limits<int>::max());
  vs.min_position_spacing_fraction = v.ranged("min_position_spacing_fraction", vs.min_position_spacing_fraction, 0.0, 1.0);
  vs.free_space_min_position_spacing_fraction =
      v.ranged("free_space_min_position_spacing_fraction", vs.free_space_min_position_spacing_fraction, 0.0, 1.0);
  vs.twist_levels = v.ranged("twist_levels", vs.twist_levels, 1, 360);
  vs.standoff_adjust_max_mm = v.non_negative("standoff_adjust_max_mm", vs.standoff_adjust_max_mm);
  vs.scan_length_design_incidence_rad = v.ranged_below("scan_length_design_incidence_rad", vs.scan_length_design_incidence_rad, 0.0, 1.5);
  vs.clearance_mm = v.non_negative("clearance_mm", vs.clearance_mm);
  vs.bisector_tilt = v.get_or<bool>("bisector_tilt", vs.bisector_tilt);
  vs.open_direction_views = v.get_or<bool>("open_direction_views", vs.open_direction_views);
  vs.open_direction_standoffs = v.ranged("open_direction_standoffs", vs.open_direction_standoffs, 1, 16);
  vs.open_directions_per_row = v.ranged("open_directions_per_row", vs.open_directions_per_row, 1, 64);
  vs.cell_native = v.get_or<bool>("cell_native", vs.cell_native);
  vs.cell_oblique_rad = v.ranged("cell_oblique_rad", vs.cell_oblique_rad, 0.0, 0.8);
  vs.cell_standoff_steps = v.ranged("cell_standoff_steps", vs.cell_standoff_steps, 1, 8);
  vs.cell_face_aim_min_angle_rad = v.ranged("cell_face_aim_min_angle_rad", vs.cell_face_aim_min_angle_rad, 0.0, 1.5);
  v.finish();
}

void read_cover(Section c, CoverSettings& cs) {
  const std::string mode = c.get_or<std::string>("mode", to_string(cs.mode));
  if (mode == "greedy") cs.mode = CoverMode::greedy;
  else if (mode == "constrained") cs.mode = CoverMode::constrained;
  else if (mode == "exact") cs.mode = CoverMode::exact;
  else c.fail(c.key_path("mode"), "must be greedy, constrained or exact, got '" + mode + "'");
  cs.registration_threshold = c.ranged("registration_threshold", cs.registration_threshold, 0.0, 1.0);
  const std::string norm = c.get_or<std::string>("registration_normalizer", to_string(cs.normalizer));
  if (norm == "max_view") cs.normalizer = RegistrationNormalizer::max_view;
  else if (norm == "smaller_view") cs.normalizer = RegistrationNormalizer::smaller_view;
  else c.fail(c.key_path("registration_normalizer"), "must be max_view or smaller_view, got '" + norm + "'");
  cs.eliminate_redundant = c.get_or<bool>("eliminate_redundant", cs.eliminate_redundant);
  cs.exact_time_limit_s = c.positive_up_to("exact_time_limit_s", cs.exact_time_limit_s, 86400.0);
  cs.min_view_gain = c.non_negative("min_view_gain_mm2", cs.min_view_gain);
  cs.local_search_iterations = whole_number(c, "local_search_iterations", cs.local_search_iterations, 0.0, 1e9);
  cs.local_search_stall_work = whole_number(c, "local_search_stall_work", cs.local_search_stall_work, 1.0, 1e15);
  cs.local_search_time_limit_s = c.positive_up_to("local_search_time_limit_s", cs.local_search_time_limit_s, 3600.0);
  c.finish();
}

void read_placement(Section s, PlacementSettings& pl) {
  using L = PlacementSettings;
  const std::string mode = s.get_or<std::string>("mode", pl.automatic ? "auto" : "as_given");
  if (mode == "auto") pl.automatic = true;
  else if (mode == "as_given") pl.automatic = false;
  else s.fail(s.key_path("mode"), "must be auto or as_given, got '" + mode + "'");
  pl.candidates = s.ranged<int>("candidates", pl.candidates, static_cast<int>(L::candidates_limits.lo),
                                static_cast<int>(L::candidates_limits.hi));
  pl.min_probability = s.ranged("min_probability", pl.min_probability, L::min_probability_limits.lo, L::min_probability_limits.hi);
  pl.min_tip_angle_rad = s.ranged("min_tip_angle_rad", pl.min_tip_angle_rad, L::min_tip_angle_limits.lo, L::min_tip_angle_limits.hi);
  pl.coverage_tolerance =
      s.ranged("coverage_tolerance", pl.coverage_tolerance, L::coverage_tolerance_limits.lo, L::coverage_tolerance_limits.hi);
  s.finish();
}

void read_matrix(Section m, PlannerSettings& p) {
  p.matrix.ray_offset_mm = m.non_negative("ray_offset_mm", p.matrix.ray_offset_mm);
  // Session 41: they apply in free space too (config.hpp).
  static constexpr std::pair<const char*, const char*> kRenamed[] = {
      {"cell_footprint_samples", "footprint_samples"}, {"cell_footprint_sample_area_mm2", "footprint_sample_area_mm2"}};
  for (const auto& [old_key, new_key] : kRenamed)
    if (m.has(old_key))
      m.fail(m.key_path(old_key), std::string("was renamed matrix.") + new_key + " (it now applies in free space too)");
  p.footprint_samples = m.ranged("footprint_samples", p.footprint_samples, 0, 64);
  p.footprint_sample_area_mm2 = m.ranged("footprint_sample_area_mm2", p.footprint_sample_area_mm2, 0.0, 1000.0);
  p.crease_footprint_samples = m.ranged("crease_footprint_samples", p.crease_footprint_samples, 0, 64);
  p.crease_angle_rad = m.ranged("crease_angle_rad", p.crease_angle_rad, 0.1, std::numbers::pi / 2);
  if (m.has("countermeasures")) {
    const YAML::Node n = m.raw("countermeasures");
    if (n.IsScalar()) {
      const std::string v = n.Scalar();
      if (v == "auto") p.countermeasures_from_cell = true;
      else if (v == "none") p.countermeasures_from_cell = false;
      else m.fail(m.key_path("countermeasures"), "must be auto, none or a mapping, got '" + v + "'");
    } else {
      p.matrix.countermeasures = parse_countermeasures(m.section("countermeasures"));
    }
  }
  if (m.has("free_space_countermeasures")) p.free_space_countermeasures = parse_countermeasures(m.section("free_space_countermeasures"));
  m.finish();
}

}  // namespace

PlannerSettings load_planner_settings(const std::filesystem::path& file, KeyDeclarations* declared) {
  YAML::Node root;
  Section y = open_root(file, root, declared);
  PlannerSettings p;
  p.seed = y.get_or<std::uint64_t>("seed", p.seed);
  if (y.has("viewpoints")) read_viewpoints(y.section("viewpoints"), p.viewpoints);
  if (y.has("cover")) read_cover(y.section("cover"), p.cover);
  if (y.has("placement")) read_placement(y.section("placement"), p.placement);
  if (y.has("matrix")) read_matrix(y.section("matrix"), p);
  y.finish();
  return p;
}

namespace {

Eigen::Isometry3d pose_from(Section& s, const std::string& translation_key, const std::string& rpy_key) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  if (s.has(translation_key)) t.translation() = s.vec3(translation_key);
  if (s.has(rpy_key)) {
    const Eigen::Vector3d r = s.vec3(rpy_key);
    t.linear() = (Eigen::AngleAxisd(r.z(), Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(r.y(), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(r.x(), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
  }
  return t;
}

Box box_from(Section& s) {
  Box b{s.vec3("min_mm"), s.vec3("max_mm")};
  if (!(b.min.array() < b.max.array()).all()) s.fail(s.key_path("max_mm"), "must exceed min_mm on every axis");
  s.finish();
  return b;
}

}  // namespace

std::size_t CellModel::axis_index(const std::string& n) const {
  for (std::size_t i = 0; i < axes.size(); ++i)
    if (axes[i].name == n) return i;
  throw ConfigError("cell " + name + ": no axis '" + n + "'");
}

JointVector CellModel::home() const {
  JointVector q;
  for (const auto& a : axes) q.push_back(a.home);
  return q;
}

namespace {

/// One axis of the cell: type, limits in the type's unit (_rad or _mm), speed, acceleration and home.
Axis read_axis(Section a, const std::string& name) {
  Axis ax;
  ax.name = name;
  const std::string type = a.get<std::string>("type");
  if (type == "rotary") ax.type = AxisType::rotary;
  else if (type == "linear") ax.type = AxisType::linear;
  else a.fail(a.key_path("type"), "must be rotary or linear, got '" + type + "'");
  const bool rot = ax.type == AxisType::rotary;
  const std::string u = rot ? "_rad" : "_mm";
  ax.min = a.get<double>("min" + u);
  ax.max = a.get<double>("max" + u);
  if (!(ax.min < ax.max)) a.fail(a.key_path("max" + u), "must be greater than min" + u);
  ax.max_speed = a.positive(rot ? "max_speed_rad_s" : "max_speed_mm_s");
  ax.max_accel = a.positive(rot ? "max_accel_rad_s2" : "max_accel_mm_s2");
  ax.home = a.get_or<double>("home" + u, std::clamp(0.0, ax.min, ax.max));
  if (!(ax.home >= ax.min && ax.home <= ax.max)) a.fail(a.key_path("home" + u), "must lie within the limits");
  a.finish();
  return ax;
}

/// The axes the kinematics names, each once, and no other.
void read_axes(Section axes, const std::string& kin, const std::vector<std::string>& names, CellModel& c) {
  for (const auto& n : names) {
    if (!axes.has(n)) axes.fail(axes.key_path(n), "missing (" + kin + " needs " + std::to_string(names.size()) + " axes)");
    c.axes.push_back(read_axis(axes.section(n), n));
  }
  for (const auto& k : axes.keys())
    if (std::find(names.begin(), names.end(), k) == names.end()) axes.fail(axes.key_path(k), "unknown axis for " + kin);
}

void read_table_axis(Section t, CellModel& c) {
  c.table_axis_point_mm = t.vec3("point_mm");
  const Eigen::Vector3d d = t.vec3("direction");
  if (!(d.norm() > 0.0) || d.normalized().z() < std::cos(0.1))
    t.fail(t.key_path("direction"), "must be within 0.1 rad of world +Z (a turntable's axis), got a vector off by more");
  c.table_axis_direction = d.normalized();
  t.finish();
}

void read_fixtures(Section& y, const std::filesystem::path& file, CellModel& c) {
  const YAML::Node list = y.raw("fixtures");
  if (!list.IsSequence()) y.fail("fixtures", "must be a list");
  for (std::size_t i = 0; i < list.size(); ++i) {
    Section f(list[i], file.string(), "fixtures[" + std::to_string(i) + "]");
    Fixture fx;
    fx.name = f.get<std::string>("name");
    const std::string frame = f.get<std::string>("frame");
    if (frame == "table") fx.on_table = true;
    else f.fail(f.key_path("frame"), "must be table (fixtures that turn with the object; world-fixed ones are not supported yet), got '" + frame + "'");
    fx.box = Box{f.vec3("min_mm"), f.vec3("max_mm")};
    if (!(fx.box.min.array() < fx.box.max.array()).all()) f.fail(f.key_path("max_mm"), "must exceed min_mm on every axis");
    f.finish();
    c.fixtures.push_back(fx);
  }
}

/// The arm's base, tool and six Denavit-Hartenberg rows [a_mm, alpha_rad, d_mm, theta_offset_rad].
void read_arm(Section arm, CellModel& c) {
  c.arm_base = pose_from(arm, "base_mm", "base_rpy_rad");
  c.tool = pose_from(arm, "tool_mm", "tool_rpy_rad");
  const YAML::Node dh = arm.raw("dh");
  if (!dh || !dh.IsSequence() || dh.size() != 6) arm.fail(arm.key_path("dh"), "must list 6 joints [a_mm, alpha_rad, d_mm, theta_offset_rad]");
  for (std::size_t i = 0; i < 6; ++i) {
    const std::string key = arm.key_path("dh[" + std::to_string(i) + "]");
    if (!dh[i].IsSequence() || dh[i].size() != 4) arm.fail(key, "must be 4 numbers");
    std::array<double, 4> row{};
    for (int k = 0; k < 4; ++k) {
      try {
        row[k] = dh[i][k].as<double>();
      } catch (const YAML::Exception&) {
        arm.fail(key, "element " + std::to_string(k) + " is not a number");
      }
      if (!std::isfinite(row[k])) arm.fail(key, "must be finite");
    }
    c.dh.push_back(row);
  }
  const std::string ik = arm.get_or<std::string>("ik", "automatic");
  if (ik == "automatic") c.arm_ik = ArmIkSolver::automatic;
  else if (ik == "numerical") c.arm_ik = ArmIkSolver::numerical;
  else if (ik == "closed_form") c.arm_ik = ArmIkSolver::closed_form;
  else arm.fail(arm.key_path("ik"), "must be automatic, closed_form or numerical, got '" + ik + "'");
  if (c.arm_ik == ArmIkSolver::closed_form && !has_ur_geometry(c.dh))
    arm.fail(arm.key_path("ik"), "closed_form needs the Universal Robots geometry (a1 = a4 = a5 = a6 = 0, d2 = d3 = 0, alpha = "
                                 "pi/2, 0, 0, pi/2, -pi/2, 0; a2, a3, d6 not 0), which dh does not have; use automatic or numerical");
  arm.finish();
}

}  // namespace

CellModel load_cell(const std::filesystem::path& file) {
  YAML::Node root;
  Section y = open_root(file, root);
  CellModel c;
  c.name = y.get_or<std::string>("name", file.stem().string());
  const std::string kin = y.get<std::string>("kinematics");
  std::vector<std::string> names;
  if (kin == "turntable_lift_tilt") {
    c.kinematics = CellKinematics::turntable_lift_tilt;
    names = {"turntable", "reach", "lift", "tilt", "sweep"};
  } else if (kin == "arm_turntable") {
    c.kinematics = CellKinematics::arm_turntable;
    names = {"turntable", "j1", "j2", "j3", "j4", "j5", "j6"};
  } else {
    y.fail("kinematics", "must be turntable_lift_tilt or arm_turntable, got '" + kin + "'");
  }
  read_axes(y.section("axes"), kin, names, c);
  c.object_on_table = pose_from(y, "object_offset_mm", "object_rpy_rad");
  if (y.has("camera_offset_mm")) c.camera_offset_mm = y.vec3("camera_offset_mm");
  if (y.has("table_axis")) read_table_axis(y.section("table_axis"), c);
  {
    Section b = y.section("scanner_body");
    c.scanner_body = box_from(b);
  }
  if (y.has("fixtures")) read_fixtures(y, file, c);
  c.clearance_mm = y.non_negative("clearance_mm", c.clearance_mm);
  c.scan_speed_mm_s = y.get_or<double>("scan_speed_mm_s", c.scan_speed_mm_s);
  if (!(c.scan_speed_mm_s > 0.0)) y.fail("scan_speed_mm_s", "must be > 0");
  if (y.has("pose_error")) {
    Section p = y.section("pose_error");
    c.pose_error.sigma_p_mm = p.non_negative("sigma_p_mm", 0.0);
    c.pose_error.sigma_a_rad = p.non_negative("sigma_a_rad", 0.0);
    c.pose_error.sigma_t_rad = p.non_negative("sigma_t_rad", 0.0);
    p.finish();
  }
  if (c.kinematics == CellKinematics::arm_turntable) read_arm(y.section("arm"), c);
  y.finish();
  return c;
}

}  // namespace scancell::planner
