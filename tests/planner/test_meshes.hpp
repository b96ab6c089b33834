#pragma once
// Synthetic geometry with known answers for the planner tests, and the shipped configs.
#include <numbers>
#include <string>

#include "planner/config.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/reconstruction/measured_coverage.hpp"

namespace scancell::planner::testing {

inline constexpr double kDeg = std::numbers::pi / 180.0;  // rad per degree

inline std::string source_path(const std::string& rel) { return std::string(SCANCELL_SOURCE_DIR) + "/" + rel; }

inline SensorModel thesis_sensor() { return load_sensor(source_path("config/sensors/line-scan-thesis.yaml")); }
inline ModelSpec thesis_spec() { return load_spec(source_path("config/spec/thesis.yaml")); }

/// WholeRowSampling by its cap and area per sample alone (no crease rows).
inline WholeRowSampling sampling(std::size_t max_samples, double sample_area_mm2 = 0.0) {
  WholeRowSampling s;
  s.max_samples = max_samples;
  s.sample_area_mm2 = sample_area_mm2;
  return s;
}

/// A committed mesh (tests/data/NAME) scaled so that its longest bounding-box side is `longest_mm`.
inline TriangleMesh test_mesh_mm(const std::string& name, double longest_mm = 200.0) {
  TriangleMesh m = load_mesh(source_path("tests/data/" + name));
  apply_scale(m, fit_scale(m, longest_mm));
  return m;
}

/// Appends a planar grid: origin + i·step·u + j·step·v for i < nu, j < nv; triangles wound so that
/// (u × v) is the front (normal) side.
inline void add_grid(TriangleMesh& m, const Eigen::Vector3d& origin, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
                     int nu, int nv, double step) {
  const auto base = static_cast<std::uint32_t>(m.vertices.size());
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) m.vertices.push_back(origin + i * step * u + j * step * v);
  auto id = [&](int i, int j) { return base + static_cast<std::uint32_t>(j * nu + i); };
  for (int j = 0; j + 1 < nv; ++j)
    for (int i = 0; i + 1 < nu; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
}

/// A flat square patch of side `side_mm` in the plane z = 0, facing +z.
inline TriangleMesh flat_patch(double side_mm, double step_mm) {
  TriangleMesh m;
  const int n = static_cast<int>(std::lround(side_mm / step_mm)) + 1;
  add_grid(m, Eigen::Vector3d(-side_mm / 2, -side_mm / 2, 0), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), n, n, step_mm);
  return m;
}

/// A square cavity of width w and depth d (floor at z = -d, rim at z = 0), inner walls facing inwards, and a
/// flat rim out to ±rim. Every face a separate grid so floor normals stay +z up to the walls.
inline TriangleMesh square_cavity(double w, double d, double rim, double step) {
  TriangleMesh m;
  const double h = w / 2;
  const int nw = static_cast<int>(std::lround(w / step)) + 1, nd = static_cast<int>(std::lround(d / step)) + 1;
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
  add_grid(m, {-h, -h, -d}, X, Y, nw, nw, step);    // floor, +z
  add_grid(m, {-h, -h, -d}, Y, Z, nw, nd, step);    // x = -h wall, normal +x
  add_grid(m, {h, -h, -d}, Z, Y, nd, nw, step);     // x = +h wall, normal -x
  add_grid(m, {-h, -h, -d}, Z, X, nd, nw, step);    // y = -h wall, normal +y
  add_grid(m, {-h, h, -d}, X, Z, nw, nd, step);     // y = +h wall, normal -y
  const int nr = static_cast<int>(std::lround((rim - h) / step)) + 1, nl = static_cast<int>(std::lround(2 * rim / step)) + 1;
  add_grid(m, {-rim, -rim, 0}, X, Y, nl, nr, step);  // rim strips, +z
  add_grid(m, {-rim, h, 0}, X, Y, nl, nr, step);
  add_grid(m, {-rim, -h, 0}, X, Y, nr, nw, step);
  add_grid(m, {h, -h, 0}, X, Y, nr, nw, step);
  return m;
}

}  // namespace scancell::planner::testing

namespace scancell::planner::testing {

/// A closed axis-aligned box with outward-facing triangles.
inline void add_box(TriangleMesh& m, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double step) {
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
  // One step for all directions: the tests use extents divisible by it.
  auto n = [&](int axis) { return static_cast<int>(std::lround((hi[axis] - lo[axis]) / step)) + 1; };
  add_grid(m, lo, Y, X, n(1), n(0), step);                                  // -z
  add_grid(m, {lo.x(), lo.y(), hi.z()}, X, Y, n(0), n(1), step);            // +z
  add_grid(m, lo, Z, Y, n(2), n(1), step);                                  // -x
  add_grid(m, {hi.x(), lo.y(), lo.z()}, Y, Z, n(1), n(2), step);            // +x
  add_grid(m, lo, X, Z, n(0), n(2), step);                                  // -y
  add_grid(m, {lo.x(), hi.y(), lo.z()}, Z, X, n(2), n(0), step);            // +y
}

/// A closed UV sphere, outward triangles.
inline TriangleMesh uv_sphere(const Eigen::Vector3d& c, double r, int rings = 90, int segments = 180) {
  TriangleMesh m;
  m.vertices.push_back(c + Eigen::Vector3d(0, 0, r));
  for (int i = 1; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const double th = M_PI * i / rings, ph = 2 * M_PI * j / segments;
      m.vertices.push_back(c + r * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)));
    }
  m.vertices.push_back(c - Eigen::Vector3d(0, 0, r));
  const auto south = static_cast<std::uint32_t>(m.vertices.size() - 1);
  auto at = [&](int i, int j) { return static_cast<std::uint32_t>(1 + (i - 1) * segments + (j % segments)); };
  for (int j = 0; j < segments; ++j) m.triangles.push_back({0, at(1, j), at(1, j + 1)});
  for (int i = 1; i < rings - 1; ++i)
    for (int j = 0; j < segments; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  for (int j = 0; j < segments; ++j) m.triangles.push_back({at(rings - 1, j), south, at(rings - 1, j + 1)});
  return m;
}

}  // namespace scancell::planner::testing
