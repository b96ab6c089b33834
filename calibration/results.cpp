#include "calibration/results.hpp"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <map>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include "common/errors.hpp"
#include "common/yaml_section.hpp"

namespace scancell::calibration {

namespace fs = std::filesystem;
namespace sp = scancell::planner;
using nlohmann::json;

namespace {

json est(const Estimate& e) { return {{"value", e.value}, {"ci95", e.ci95}}; }
json vec(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

void emit(YAML::Emitter& out, const json& j) {
  if (j.is_object()) {
    out << YAML::BeginMap;
    for (const auto& [k, v] : j.items()) {
      out << YAML::Key << k << YAML::Value;
      emit(out, v);
    }
    out << YAML::EndMap;
  } else if (j.is_array()) {
    out << YAML::Flow << YAML::BeginSeq;
    for (const auto& v : j) emit(out, v);
    out << YAML::EndSeq;
  } else if (j.is_number_integer()) {
    out << j.get<long long>();
  } else if (j.is_number()) {
    char b[40];
    std::snprintf(b, sizeof b, "%.10g", j.get<double>());
    out << b;
  } else if (j.is_boolean()) {
    out << j.get<bool>();
  } else if (j.is_string()) {
    out << j.get<std::string>();
  } else {
    out << YAML::Null;
  }
}

json to_json(const YAML::Node& n) {
  if (n.IsMap()) {
    json o = json::object();
    for (const auto& kv : n) o[kv.first.as<std::string>()] = to_json(kv.second);
    return o;
  }
  if (n.IsSequence()) {
    json a = json::array();
    for (const auto& v : n) a.push_back(to_json(v));
    return a;
  }
  if (n.IsScalar()) {
    try {
      std::size_t used = 0;
      const double d = std::stod(n.Scalar(), &used);
      if (used == n.Scalar().size()) return d;
    } catch (const std::exception&) {
    }
    return n.Scalar();
  }
  return nullptr;
}

double number(const CalibrationRecord& r, const std::string& name, const std::string& file) {
  const auto it = r.values.find(name);
  if (it == r.values.end() || !it->is_object() || !it->contains("value") || !(*it)["value"].is_number())
    throw scancell::ConfigError(file + ": values." + name + ": missing or not {value, ci95}");
  const double v = (*it)["value"].get<double>();
  if (!std::isfinite(v)) throw scancell::ConfigError(file + ": values." + name + ".value: not finite");
  return v;
}

Eigen::Vector3d vector3(const CalibrationRecord& r, const std::string& name, const std::string& file) {
  const auto it = r.values.find(name);
  if (it == r.values.end() || !it->contains("value") || !(*it)["value"].is_array() || (*it)["value"].size() != 3)
    throw scancell::ConfigError(file + ": values." + name + ": missing or not {value: [x, y, z], ci95}");
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    const auto& e = (*it)["value"][static_cast<std::size_t>(k)];
    if (!e.is_number()) throw scancell::ConfigError(file + ": values." + name + ".value[" + std::to_string(k) + "]: not a number");
    v[k] = e.get<double>();
  }
  return v;
}

}  // namespace

std::string utc_now_iso() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

CalibrationRecord record_of(const SensorResult& r, const std::string& cell) {
  CalibrationRecord c{"sensor", utc_now_iso(), cell};
  json noise = json::array();
  for (const auto& n : r.noise) noise.push_back({{"depth_mm", n.depth_mm}, {"sigma_z_mm", n.sigma_z_mm}, {"samples", n.samples}});
  c.inputs = {{"scans", r.scans}, {"plate_standoffs", r.noise.size()}, {"ramp_scans", r.yield_vs_theta_yz.size()}};
  c.values = {{"noise_cz_per_mm", est(r.cz_per_mm)}, {"noise_cx", est(r.cx)}, {"noise_cy", est(r.cy)},
              {"grazing_xz_rad", est(r.t_xz_rad)}, {"grazing_yz_rad", est(r.t_yz_rad)}};
  c.residuals = {{"noise_fit_rms_mm", r.noise_fit_rms_mm}, {"noise_by_depth", noise}};
  return c;
}

CalibrationRecord record_of(const AxisResult& r, const std::string& cell) {
  CalibrationRecord c{"turntable_axis", utc_now_iso(), cell};
  c.inputs = {{"scans", r.scans}, {"circle_radius_mm", r.circle_radius_mm}};
  c.values = {{"table_axis_point_mm", {{"value", vec(r.point_mm)}, {"ci95", r.point_ci95_mm}}},
              {"table_axis_direction", {{"value", vec(r.direction)}, {"ci95", r.direction_ci95_rad}}}};
  c.residuals = {{"circle_rms_mm", r.circle_rms_mm}, {"sphere_rms_mm", r.sphere_rms_mm}};
  return c;
}

CalibrationRecord record_of(const PositionerResult& r, const std::string& cell) {
  CalibrationRecord c{"positioner", utc_now_iso(), cell};
  c.inputs = {{"scans", r.scans}};
  c.values = {{"sigma_p_mm", est(r.sigma_p_mm)}, {"sigma_a_rad", est(r.sigma_a_rad)}, {"sigma_t_rad", est(r.sigma_t_rad)}};
  c.residuals = {{"sphere_rms_mm", r.sphere_rms_mm}};
  return c;
}

void write_calibration(const fs::path& file, const CalibrationRecord& r) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  out << YAML::Key << "scancell_calibration" << YAML::Value << 1;
  out << YAML::Key << "kind" << YAML::Value << r.kind;
  out << YAML::Key << "date" << YAML::Value << r.date;
  out << YAML::Key << "cell" << YAML::Value << r.cell;
  out << YAML::Key << "inputs" << YAML::Value;
  emit(out, r.inputs);
  out << YAML::Key << "values" << YAML::Value;
  emit(out, r.values);
  out << YAML::Key << "residuals" << YAML::Value;
  emit(out, r.residuals);
  out << YAML::EndMap;
  fs::create_directories(file.parent_path());
  const fs::path tmp = file.string() + ".tmp";
  {
    std::ofstream f(tmp);
    f << "# scancell calibration result (docs/calibration.md). Lengths mm, angles rad; ci95: 95 % half-width.\n"
      << out.c_str() << "\n";
    if (!f.flush()) throw std::runtime_error(tmp.string() + ": write failed");
  }
  const int fd = ::open(tmp.c_str(), O_RDONLY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
  fs::rename(tmp, file);
}

CalibrationRecord load_calibration(const fs::path& file) {
  YAML::Node holder;
  scancell::Section y = scancell::open_root(file, holder);
  const int version = y.get<int>("scancell_calibration");
  if (version != 1) y.fail("scancell_calibration", "version " + std::to_string(version) + " is not supported (1 is)");
  CalibrationRecord r;
  r.kind = y.get<std::string>("kind");
  if (r.kind != "sensor" && r.kind != "turntable_axis" && r.kind != "positioner")
    y.fail("kind", "must be sensor, turntable_axis or positioner, got '" + r.kind + "'");
  r.date = y.get<std::string>("date");
  r.cell = y.get<std::string>("cell");
  r.inputs = to_json(y.raw("inputs"));
  r.values = to_json(y.raw("values"));
  if (y.has("residuals")) r.residuals = to_json(y.raw("residuals"));
  y.finish();
  // Check the values now, so that a bad file is refused before anything is applied.
  sp::SensorModel s;
  sp::CellModel c;
  c.name = r.cell;
  apply_calibration(r, s, c);
  (void)file;
  return r;
}

std::vector<std::string> apply_calibration(const CalibrationRecord& r, sp::SensorModel& s, sp::CellModel& c) {
  const std::string where = "calibration " + r.kind + " of " + r.date;
  if (r.cell != c.name) throw scancell::ConfigError(where + ": made on cell '" + r.cell + "', this is '" + c.name + "'");
  std::vector<std::string> changes;
  auto set = [&](const char* name, double& field, double v, double lo, double hi) {
    if (!(v > lo && v < hi)) throw scancell::ConfigError(where + ": values." + name + " " + std::to_string(v) + " outside (" + std::to_string(lo) + ", " + std::to_string(hi) + ")");
    if (field != v) changes.push_back(std::string(name) + ": " + std::to_string(field) + " -> " + std::to_string(v));
    field = v;
  };
  if (r.kind == "sensor") {
    set("noise_cz_per_mm", s.noise_cz_per_mm, number(r, "noise_cz_per_mm", where), 0.0, 1e-3);
    // Older sensor files may lack the lateral coefficients: they then leave them as they are.
    if (r.values.contains("noise_cx")) set("noise_cx", s.noise_cx, number(r, "noise_cx", where), -1e-12, 1e-2);
    if (r.values.contains("noise_cy")) set("noise_cy", s.noise_cy, number(r, "noise_cy", where), -1e-12, 1e-2);
    set("grazing_xz_rad", s.grazing_xz_rad, number(r, "grazing_xz_rad", where), 0.0, 1.5707963267948966);
    set("grazing_yz_rad", s.grazing_yz_rad, number(r, "grazing_yz_rad", where), 0.0, 1.5707963267948966);
  } else if (r.kind == "turntable_axis") {
    const Eigen::Vector3d p = vector3(r, "table_axis_point_mm", where), d = vector3(r, "table_axis_direction", where);
    if (!(d.norm() > 0.5 && d.normalized().z() > std::cos(0.1)))
      throw scancell::ConfigError(where + ": values.table_axis_direction is not within 0.1 rad of +Z");
    if (!(p.head<2>().norm() < 50.0)) throw scancell::ConfigError(where + ": values.table_axis_point_mm more than 50 mm off the nominal axis");
    if ((c.table_axis_point_mm - p).norm() > 0.0 || (c.table_axis_direction - d.normalized()).norm() > 0.0) {
      std::ostringstream os;
      os << "turntable axis: point [" << c.table_axis_point_mm.transpose() << "] -> [" << p.transpose() << "] mm, direction ["
         << c.table_axis_direction.transpose() << "] -> [" << d.normalized().transpose() << "]";
      changes.push_back(os.str());
    }
    c.table_axis_point_mm = p;
    c.table_axis_direction = d.normalized();
  } else {
    set("sigma_p_mm", c.pose_error.sigma_p_mm, number(r, "sigma_p_mm", where), -1e-12, 10.0);
    set("sigma_a_rad", c.pose_error.sigma_a_rad, number(r, "sigma_a_rad", where), -1e-12, 0.2);
    set("sigma_t_rad", c.pose_error.sigma_t_rad, number(r, "sigma_t_rad", where), -1e-12, 0.2);
  }
  return changes;
}

std::vector<fs::path> latest_calibrations(const fs::path& dir) {
  std::map<std::string, fs::path> newest;
  if (!fs::exists(dir)) return {};
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() != ".yaml") continue;
    const auto dash = name.find('-');
    if (dash == std::string::npos) continue;
    const std::string kind = name.substr(0, dash);
    if (!newest.count(kind) || newest[kind].filename().string() < name) newest[kind] = e.path();
  }
  std::vector<fs::path> out;
  for (const auto& [k, p] : newest) out.push_back(p);
  return out;
}

}  // namespace scancell::calibration
