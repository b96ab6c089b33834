#include "planner/plan_file.hpp"

#include "common/json_input.hpp"

#include <cmath>
#include <fstream>

#include <nlohmann/json.hpp>

#include "planner/kinematics/cell.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"

namespace scancell::planner {
namespace {

using nlohmann::json;

struct Reader {
  std::string file;
  [[noreturn]] void fail(const std::string& at, const std::string& why) const { throw DataError(file + ": " + at + ": " + why); }

  const json& member(const json& o, const std::string& at, const std::string& key) const {
    if (!o.is_object()) fail(at, "must be an object");
    const auto it = o.find(key);
    if (it == o.end()) fail(at.empty() ? key : at + "." + key, "missing");
    return *it;
  }
  double number(const json& v, const std::string& at) const {
    if (!v.is_number()) fail(at, "must be a number");
    const double d = v.get<double>();
    if (!std::isfinite(d)) fail(at, "must be finite");
    return d;
  }
  Eigen::Matrix4d matrix(const json& v, const std::string& at) const {
    if (!v.is_array() || v.size() != 16) fail(at, "must be an array of 16 numbers (row major)");
    Eigen::Matrix4d m;
    for (int k = 0; k < 16; ++k) m(k / 4, k % 4) = number(v[k], at + "[" + std::to_string(k) + "]");
    if (!m.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1))) fail(at, "last row must be 0 0 0 1");
    return m;
  }
};

}  // namespace

PlanFile load_plan_file(const std::filesystem::path& path) {
  Reader r{path.string()};
  std::ifstream f(path);
  if (!f) throw DataError(r.file + ": cannot open file");
  json j;
  try {
    // A plan nests 4 levels; 32 leaves room and refuses a hostile file before anything recurses on it.
    j = parse_json_input(f, JsonLimits{32, true});
  } catch (const JsonInputError& e) {
    throw DataError(r.file + ": " + e.what());
  }
  PlanFile p;
  p.path = r.file;
  const json& format = r.member(j, "", "format");
  if (format != "scancell-plan") r.fail("format", "is not \"scancell-plan\"");
  if (r.member(j, "", "version") != 1) r.fail("version", "unsupported (this build reads version 1)");
  const json& object = r.member(j, "", "object");
  const json& mesh = r.member(object, "object", "mesh");
  if (!mesh.is_string()) r.fail("object.mesh", "must be a string");
  p.mesh_path = mesh.get<std::string>();
  p.object_transform = r.matrix(r.member(object, "object", "transform_row_major"), "object.transform_row_major");
  if (!(p.object_transform.topLeftCorner<3, 3>().determinant() > 0.0))
    r.fail("object.transform_row_major", "must preserve orientation (determinant > 0)");
  p.sensor = parse_sensor(r.member(j, "", "sensor").dump(), r.file + ": sensor");
  p.spec = parse_spec(r.member(j, "", "spec").dump(), r.file + ": spec");
  const json& views = r.member(j, "", "views");
  if (!views.is_array()) r.fail("views", "must be an array");
  for (std::size_t k = 0; k < views.size(); ++k) {
    const std::string at = "views[" + std::to_string(k) + "]";
    const json& v = views[k];
    const Eigen::Matrix4d m = r.matrix(r.member(v, at, "camera_to_object_row_major"), at + ".camera_to_object_row_major");
    const Eigen::Matrix3d rot = m.topLeftCorner<3, 3>();
    if (!(rot.transpose() * rot).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || rot.determinant() < 0.0)
      r.fail(at + ".camera_to_object_row_major", "rotation part is not a rotation");
    ScanPose pose;
    pose.camera_to_object.matrix() = m;
    pose.scan_length_mm = r.number(r.member(v, at, "scan_length_mm"), at + ".scan_length_mm");
    if (p.sensor.kind == SensorKind::line_scan && !(pose.scan_length_mm > 0.0)) r.fail(at + ".scan_length_mm", "must be > 0");
    const double est = v.contains("cumulative_estimated_measurability")
                           ? r.number(v["cumulative_estimated_measurability"], at + ".cumulative_estimated_measurability")
                           : std::nan("");
    p.views.push_back(pose);
    p.viewpoints.push_back(viewpoint_from_pose(rot, m.topRightCorner<3, 1>(), pose.scan_length_mm));
    p.estimated_cumulative.push_back(est);
  }
  if (j.contains("cell")) {
    const json& cell = j["cell"];
    const json& name = r.member(cell, "cell", "name");
    if (!name.is_string()) r.fail("cell.name", "must be a string");
    p.cell = name.get<std::string>();
    p.object_on_table = r.matrix(r.member(cell, "cell", "object_on_table_row_major"), "cell.object_on_table_row_major");
    if (cell.contains("fixtures")) {
      const json& fx = cell["fixtures"];
      if (!fx.is_array()) r.fail("cell.fixtures", "must be an array");
      for (std::size_t k = 0; k < fx.size(); ++k) {
        const std::string at = "cell.fixtures[" + std::to_string(k) + "]";
        Eigen::Vector3d lo, hi;
        for (auto [key, out] : {std::pair<const char*, Eigen::Vector3d*>{"min_mm", &lo}, {"max_mm", &hi}}) {
          const json& v = r.member(fx[k], at, key);
          if (!v.is_array() || v.size() != 3) r.fail(at + "." + key, "must be 3 numbers");
          for (int i = 0; i < 3; ++i) (*out)[i] = r.number(v[i], at + "." + key);
        }
        if (!(lo.array() < hi.array()).all()) r.fail(at + ".max_mm", "must exceed min_mm");
        p.table_fixtures.emplace_back(lo, hi);
      }
    }
  }
  return p;
}

TriangleMesh PlanFile::fixtures_in_object_frame() const {
  CellModel c;
  Eigen::Isometry3d t;
  t.matrix() = object_on_table;
  c.object_on_table = t;
  for (const auto& [lo, hi] : table_fixtures) c.fixtures.push_back({"fixture", true, {lo, hi}});
  return fixture_mesh(c);
}

}  // namespace scancell::planner
