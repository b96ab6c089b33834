#include "planner/reconstruction/rough_scan.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <unordered_map>

#include "common/errors.hpp"

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
  // The sweep runs horizontally; the profile's fan (Φx) spans the height. An object taller than ~80 % of the
  // fan's width at the stand-off is explored at several aim heights, evenly up the box, so that no band of it
  // is left to the fusion's guess.
  const double fan_mm = 2.0 * standoff * std::tan(0.5 * sensor.fov_x_rad);
  const int levels = std::max(1, static_cast<int>(std::ceil(size.z() / (0.8 * fan_mm))));
  std::vector<ExplorationView> out;
  for (int level = 0; level < levels; ++level) {
    const Eigen::Vector3d aim(0.0, 0.0, size.z() * (level + 0.5) / levels);
    for (double tilt : o.tilts_rad)
      for (int k = 0; k < o.table_steps; ++k) {
        const double table = -std::numbers::pi + 2.0 * std::numbers::pi * k / o.table_steps;
        const IkResult ik = look_at(cell, aim, standoff, tilt, table, length);
        if (!ik.ok) {
          if (skipped)
            skipped->push_back("aim height " + std::to_string(aim.z()) + " mm, table " + std::to_string(table) + " rad, tilt " +
                               std::to_string(tilt) + " rad: " + ik.why);
          continue;
        }
        out.push_back({ik.q, length});
      }
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

namespace {

// 1 µm grid cells: a vertex written with 6 decimals and read back in single precision lands in its own cell
// or a neighbour.
std::uint64_t micro_key(long x, long y, long z) {
  return (static_cast<std::uint64_t>(x & 0x1fffff) << 42) | (static_cast<std::uint64_t>(y & 0x1fffff) << 21) | static_cast<std::uint64_t>(z & 0x1fffff);
}

}  // namespace

void write_flagged_vertices(const TriangleMesh& m, const std::vector<std::uint8_t>& flags, const std::string& path) {
  if (flags.size() != m.vertices.size())
    throw DataError(path + ": " + std::to_string(flags.size()) + " flags for " + std::to_string(m.vertices.size()) + " vertices");
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    f << "# hypothetical rough-model vertices (unseen space closed conservatively): x y z, mm, object frame\n";
    char b[96];
    for (std::size_t i = 0; i < flags.size(); ++i)
      if (flags[i]) {
        std::snprintf(b, sizeof b, "%.6f %.6f %.6f\n", m.vertices[i].x(), m.vertices[i].y(), m.vertices[i].z());
        f << b;
      }
    if (!f.flush()) throw std::runtime_error(path + ": write failed");
  }
  std::filesystem::rename(tmp, path);
}

std::vector<std::uint8_t> read_flagged_vertices(const TriangleMesh& m, const std::string& path) {
  std::ifstream f(path);
  if (!f) throw DataError(path + ": cannot read");
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> at;
  for (std::uint32_t i = 0; i < m.vertices.size(); ++i) {
    const Eigen::Vector3d& v = m.vertices[i];
    at[micro_key(std::lround(v.x() * 1e3), std::lround(v.y() * 1e3), std::lround(v.z() * 1e3))].push_back(i);
  }
  std::vector<std::uint8_t> out(m.vertices.size(), 0);
  std::string line;
  for (int n = 1; std::getline(f, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    Eigen::Vector3d p;
    if (!(in >> p.x() >> p.y() >> p.z()) || !p.allFinite())
      throw DataError(path + ":" + std::to_string(n) + ": expected x y z (mm), got '" + line + "'");
    const long x = std::lround(p.x() * 1e3), y = std::lround(p.y() * 1e3), z = std::lround(p.z() * 1e3);
    bool found = false;
    for (long dx = -1; dx <= 1; ++dx)
      for (long dy = -1; dy <= 1; ++dy)
        for (long dz = -1; dz <= 1; ++dz) {
          const auto it = at.find(micro_key(x + dx, y + dy, z + dz));
          if (it == at.end()) continue;
          for (auto i : it->second)
            if ((m.vertices[i] - p).norm() < 2e-3) {
              out[i] = 1;
              found = true;
            }
        }
    if (!found) throw DataError(path + ":" + std::to_string(n) + ": no vertex of the rough model at " + line + " (not this model's list)");
  }
  return out;
}

}  // namespace scancell::planner
