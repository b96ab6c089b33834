#include "calibration/targets.hpp"

#include <cmath>
#include <numbers>

namespace scancell::calibration {

namespace sp = scancell::planner;

namespace {

void add_quad(sp::TriangleMesh& m, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
              const Eigen::Vector3d& d) {
  const auto i = static_cast<std::uint32_t>(m.vertices.size());
  m.vertices.insert(m.vertices.end(), {a, b, c, d});
  m.triangles.push_back({i, i + 1, i + 2});
  m.triangles.push_back({i, i + 2, i + 3});
}

}  // namespace

sp::TriangleMesh plate_target(double side, double t) {
  sp::TriangleMesh m;
  const double h = side / 2;
  // Counter-clockwise seen from outside.
  add_quad(m, {-h, -h, t}, {h, -h, t}, {h, h, t}, {-h, h, t});      // top
  add_quad(m, {-h, -h, 0}, {-h, h, 0}, {h, h, 0}, {h, -h, 0});      // bottom
  add_quad(m, {-h, -h, 0}, {h, -h, 0}, {h, -h, t}, {-h, -h, t});    // y = -h
  add_quad(m, {h, h, 0}, {-h, h, 0}, {-h, h, t}, {h, h, t});        // y = +h
  add_quad(m, {h, -h, 0}, {h, h, 0}, {h, h, t}, {h, -h, t});        // x = +h
  add_quad(m, {-h, h, 0}, {-h, -h, 0}, {-h, -h, t}, {-h, h, t});    // x = -h
  return m;
}

Eigen::Vector3d Ramp::normal() const { return {0.0, std::sin(slope_rad), std::cos(slope_rad)}; }
Eigen::Vector3d Ramp::centre() const { return offset_mm + Eigen::Vector3d(0.0, 0.0, half_depth_mm * std::tan(slope_rad)); }

bool on_ramp_face(const Ramp& r, const Eigen::Vector3d& p, double margin, double tol) {
  const Eigen::Vector3d t = p - r.offset_mm;
  const double h = (r.half_depth_mm - t.y()) * std::tan(r.slope_rad);
  return std::abs(t.x()) < r.half_width_mm - margin && std::abs(t.y()) < r.half_depth_mm - margin &&
         std::abs(t.z() - h) * std::cos(r.slope_rad) < tol;
}

sp::TriangleMesh sensor_target(const Ramp& ramp) {
  sp::TriangleMesh m = plate_target(kPlateSideMm, kPlateThicknessMm);
  sp::append_mesh(m, ramp_target(ramp));
  return m;
}

sp::TriangleMesh ramp_target(const Ramp& r) {
  sp::TriangleMesh m;
  const double w = r.half_width_mm, d = r.half_depth_mm, top = 2 * d * std::tan(r.slope_rad);
  const std::size_t first = m.vertices.size();
  add_quad(m, {-w, -d, top}, {w, -d, top}, {w, d, 0}, {-w, d, 0});  // the sloped face, high at y = -d
  add_quad(m, {-w, -d, 0}, {-w, d, 0}, {w, d, 0}, {w, -d, 0});      // bottom
  add_quad(m, {-w, -d, 0}, {w, -d, 0}, {w, -d, top}, {-w, -d, top}); // back, y = -d
  const auto i = static_cast<std::uint32_t>(m.vertices.size());
  m.vertices.insert(m.vertices.end(), {{w, -d, 0}, {w, d, 0}, {w, -d, top}, {-w, -d, 0}, {-w, -d, top}, {-w, d, 0}});
  m.triangles.push_back({i, i + 1, i + 2});      // x = +w side
  m.triangles.push_back({i + 3, i + 4, i + 5});  // x = -w side
  for (std::size_t k = first; k < m.vertices.size(); ++k) m.vertices[k] += r.offset_mm;
  return m;
}

sp::TriangleMesh spheres_target(const Spheres& s) {
  sp::TriangleMesh m;
  const int rings = 180, segments = 360;  // 0.5°: chord sagitta r(1 - cos 0.25°) < 0.0002 mm at r = 12.5 mm
  for (const auto& c : s.centres) {
    const auto base = static_cast<std::uint32_t>(m.vertices.size());
    m.vertices.push_back(c + Eigen::Vector3d(0, 0, s.radius_mm));
    for (int i = 1; i < rings; ++i) {
      const double th = std::numbers::pi * i / rings;
      for (int j = 0; j < segments; ++j) {
        const double ph = 2 * std::numbers::pi * j / segments;
        m.vertices.push_back(c + s.radius_mm * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)));
      }
    }
    m.vertices.push_back(c - Eigen::Vector3d(0, 0, s.radius_mm));
    const std::uint32_t south = static_cast<std::uint32_t>(m.vertices.size() - 1);
    auto ring = [&](int i, int j) { return base + 1 + static_cast<std::uint32_t>((i - 1) * segments + (j % segments)); };
    for (int j = 0; j < segments; ++j) m.triangles.push_back({base, ring(1, j), ring(1, j + 1)});
    for (int i = 1; i < rings - 1; ++i)
      for (int j = 0; j < segments; ++j) {
        m.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
        m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
      }
    for (int j = 0; j < segments; ++j) m.triangles.push_back({ring(rings - 1, j), south, ring(rings - 1, j + 1)});
  }
  return m;
}

Spheres axis_sphere(double r, double h) { return {12.5, {Eigen::Vector3d(r, 0.0, h)}}; }

Spheres tripod() {
  return {12.5, {Eigen::Vector3d(45.0, 0.0, 40.0), Eigen::Vector3d(-22.5, 39.0, 55.0), Eigen::Vector3d(-22.5, -39.0, 70.0)}};
}

}  // namespace scancell::calibration
