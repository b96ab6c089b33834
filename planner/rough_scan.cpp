#include "planner/rough_scan.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "planner/errors.hpp"

namespace scancell::planner {

Eigen::AlignedBox3d exploration_bounds(const Eigen::Vector3d& s) {
  const Eigen::Vector3d margin = Eigen::Vector3d::Constant(10.0);
  return Eigen::AlignedBox3d(Eigen::Vector3d(-0.5 * s.x(), -0.5 * s.y(), 0.0) - margin, Eigen::Vector3d(0.5 * s.x(), 0.5 * s.y(), s.z()) + margin);
}

std::vector<ExplorationView> exploration_views(const CellModel& cell, const SensorModel& sensor, const Eigen::Vector3d& size,
                                               const ExplorationOptions& o, std::vector<std::string>* skipped) {
  if (!(size.minCoeff() > 0.0)) throw DataError("rough scan: the object's size must be positive in x, y and z");
  const double radius = 0.5 * size.norm();
  if (2.0 * radius > sensor.range_max_mm - sensor.range_min_mm)
    throw DataError("rough scan: an object " + std::to_string(static_cast<int>(2 * radius)) + " mm across does not fit the sensor's depth of field (" +
                    std::to_string(static_cast<int>(sensor.range_max_mm - sensor.range_min_mm)) + " mm)");
  // The centre mid-range: the near side beyond R_min, the far side within R_max.
  const double standoff = std::min(sensor.range_max_mm - radius - 5.0, std::max(sensor.range_min_mm + radius + 5.0, 0.5 * (sensor.range_min_mm + sensor.range_max_mm)));
  const double length = std::clamp(2.0 * radius, sensor.scan_length_min_mm, sensor.scan_length_max_mm);
  const Eigen::Vector3d centre(0.0, 0.0, 0.5 * size.z());
  std::vector<ExplorationView> out;
  for (double tilt : o.tilts_rad)
    for (int k = 0; k < o.table_steps; ++k) {
      const double table = -std::numbers::pi + 2.0 * std::numbers::pi * k / o.table_steps;
      const IkResult ik = look_at(cell, centre, standoff, tilt, table, length);
      if (!ik.ok) {
        if (skipped) skipped->push_back("table " + std::to_string(table) + " rad, tilt " + std::to_string(tilt) + " rad: " + ik.why);
        continue;
      }
      out.push_back({ik.q, length});
    }
  if (out.empty()) throw DataError("rough scan: the cell reaches none of the exploration poses");
  return out;
}

void write_off(const TriangleMesh& m, const std::string& path) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    f << "OFF\n" << m.vertices.size() << ' ' << m.triangles.size() << " 0\n";
    char b[96];
    for (const auto& v : m.vertices) {
      std::snprintf(b, sizeof b, "%.6f %.6f %.6f\n", v.x(), v.y(), v.z());
      f << b;
    }
    for (const auto& t : m.triangles) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
    if (!f.flush()) throw std::runtime_error(path + ": write failed");
  }
  std::filesystem::rename(tmp, path);
}

}  // namespace scancell::planner
