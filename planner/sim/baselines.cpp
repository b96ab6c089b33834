#include "planner/sim/baselines.hpp"

#include <cmath>
#include <map>
#include <numbers>
#include <stdexcept>

namespace scancell::planner {
namespace {

Eigen::AlignedBox3d bounds(const TriangleMesh& m) {
  Eigen::AlignedBox3d box;
  for (const auto& v : m.vertices) box.extend(v);
  return box;
}

Viewpoint looking_at(const Eigen::Vector3d& centre, const Eigen::Vector3d& from_dir, double distance, double twist,
                     double scan_length) {
  Viewpoint v;
  v.position = centre + distance * from_dir;
  v.axis = -from_dir;
  v.twist_rad = twist;
  v.standoff_mm = distance;
  v.scan_length_mm = scan_length;
  return v;
}

}  // namespace

double baseline_standoff_mm(const TriangleMesh& object, const SensorModel& s) {
  const double radius = 0.5 * bounds(object).sizes().norm();
  return std::min(s.range_min_mm + radius, s.range_max_mm);
}

std::vector<Viewpoint> turntable_program(const TriangleMesh& object, const SensorModel& s, const ModelSpec& spec,
                                         int steps, const std::vector<double>& elevations, double incidence) {
  if (steps < 1) throw std::invalid_argument("turntable_program: steps must be >= 1");
  const Eigen::Vector3d c = bounds(object).center();
  const double d = baseline_standoff_mm(object, s);
  const double len = design_scan_length_mm(s, spec, d, incidence);
  std::vector<Viewpoint> out;
  for (double e : elevations)
    for (int k = 0; k < steps; ++k) {
      const double a = 2.0 * std::numbers::pi * k / steps;
      const Eigen::Vector3d dir(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
      const Eigen::Vector3d tangent(-std::sin(a), std::cos(a), 0.0);
      out.push_back(looking_at(c, dir, d, twist_towards(-dir, tangent), len));
    }
  return out;
}

std::vector<Eigen::Vector3d> icosphere_directions(int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<Triangle> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                             {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                             {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = static_cast<std::uint32_t>(v.size() - 1);
    };
    std::vector<Triangle> next;
    for (const auto& tri : f) {
      const auto ab = midpoint(tri[0], tri[1]), bc = midpoint(tri[1], tri[2]), ca = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    f = std::move(next);
  }
  return v;
}

std::vector<Viewpoint> view_sphere_candidates(const TriangleMesh& object, const SensorModel& s, const ModelSpec& spec,
                                              int subdivisions, int twist_levels, double incidence) {
  if (twist_levels < 1) throw std::invalid_argument("view_sphere_candidates: twist_levels must be >= 1");
  const Eigen::Vector3d c = bounds(object).center();
  const double d = baseline_standoff_mm(object, s);
  const double len = design_scan_length_mm(s, spec, d, incidence);
  std::vector<Viewpoint> out;
  for (const auto& dir : icosphere_directions(subdivisions))
    for (int k = 0; k < twist_levels; ++k) {
      Viewpoint v = looking_at(c, dir, d, 2.0 * std::numbers::pi * k / twist_levels, len);
      v.twist_level = k;
      out.push_back(v);
    }
  return out;
}

}  // namespace scancell::planner
