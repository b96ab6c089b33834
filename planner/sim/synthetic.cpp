#include "planner/sim/synthetic.hpp"

#include <cmath>
#include <functional>
#include <map>
#include <numbers>
#include <random>
#include <stdexcept>
#include <tuple>

#include "planner/core/viewpoint.hpp"

namespace scancell::planner {
namespace {

using Point = std::function<Eigen::Vector3d(int, int)>;
using Outward = std::function<Eigen::Vector3d(const Eigen::Vector3d&)>;

int segments(double length_mm, double spacing_mm) { return std::max(1, static_cast<int>(std::ceil(length_mm / spacing_mm - 1e-9))); }

/// A (nu × nv)-quad grid of points P(iu, iv), iu in [0, nu] (or periodic: iu = nu is iu = 0), each quad split
/// into two triangles wound so their normals agree with `outward`. Zero-area triangles (a grid collapsing to a
/// point, e.g. a disc's centre) are skipped.
void add_grid(TriangleMesh& m, int nu, int nv, bool periodic_u, const Point& P, const Outward& outward) {
  const int cols = periodic_u ? nu : nu + 1;
  const std::uint32_t base = static_cast<std::uint32_t>(m.vertices.size());
  for (int iv = 0; iv <= nv; ++iv)
    for (int iu = 0; iu < cols; ++iu) m.vertices.push_back(P(iu, iv));
  auto id = [&](int iu, int iv) { return base + static_cast<std::uint32_t>(iv * cols + (periodic_u ? iu % nu : iu)); };
  auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    const Eigen::Vector3d& pa = m.vertices[a];
    const Eigen::Vector3d n = (m.vertices[b] - pa).cross(m.vertices[c] - pa);
    if (n.norm() < 1e-12) return;
    const Eigen::Vector3d centre = (pa + m.vertices[b] + m.vertices[c]) / 3.0;
    if (n.dot(outward(centre)) >= 0.0) m.triangles.push_back({a, b, c});
    else m.triangles.push_back({a, c, b});
  };
  for (int iv = 0; iv < nv; ++iv)
    for (int iu = 0; iu < nu; ++iu) {
      add(id(iu, iv), id(iu + 1, iv), id(iu + 1, iv + 1));
      add(id(iu, iv), id(iu + 1, iv + 1), id(iu, iv + 1));
    }
}

Outward constant(const Eigen::Vector3d& d) {
  return [d](const Eigen::Vector3d&) { return d; };
}

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(what);
}

}  // namespace

double sensor_footprint_mm2(const SensorModel& s, const ModelSpec& spec, double f_d, double incidence) {
  const double r = f_d * s.optimal_standoff_mm;
  const double width = 2.0 * r * std::tan(0.5 * s.fov_x_rad);
  const double length = s.kind == SensorKind::line_scan ? design_scan_length_mm(s, spec, r, incidence)
                                                        : 2.0 * r * std::tan(0.5 * s.fov_y_rad);
  return width * length;
}

TriangleMesh weld(const TriangleMesh& mesh, double tol) {
  std::map<std::tuple<long long, long long, long long>, std::uint32_t> index;
  std::vector<std::uint32_t> remap(mesh.vertices.size());
  TriangleMesh out;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto& p = mesh.vertices[i];
    const auto key = std::make_tuple(std::llround(p.x() / tol), std::llround(p.y() / tol), std::llround(p.z() / tol));
    auto [it, fresh] = index.emplace(key, static_cast<std::uint32_t>(out.vertices.size()));
    if (fresh) out.vertices.push_back(p);
    remap[i] = it->second;
  }
  for (const auto& t : mesh.triangles) {
    const Triangle r{remap[t[0]], remap[t[1]], remap[t[2]]};
    if (r[0] != r[1] && r[1] != r[2] && r[0] != r[2]) out.triangles.push_back(r);
  }
  return out;
}

TriangleMesh convex_patch(double w, double dw, double sp) {
  require(w > 0 && dw >= 0 && sp > 0, "convex_patch: sizes must be positive");
  TriangleMesh m;
  const int n = segments(w, sp);
  const double d = dw * w;
  add_grid(m, n, n, false, [&](int i, int j) {
    const double x = -0.5 * w + w * i / n, y = -0.5 * w + w * j / n;
    return Eigen::Vector3d(x, y, d * (1.0 - (x * x + y * y) / (0.5 * w * w)));
  }, constant(Eigen::Vector3d::UnitZ()));
  return m;
}

TriangleMesh cavity_patch(double plate, double cw, double dw, double sp) {
  require(plate > 0 && cw > 0 && cw <= plate && dw >= 0 && sp > 0, "cavity_patch: need 0 < cavity width <= plate");
  TriangleMesh m;
  const int n = segments(plate, sp);
  const double d = dw * cw, rim = 0.5 * cw;
  add_grid(m, n, n, false, [&](int i, int j) {
    const double x = -0.5 * plate + plate * i / n, y = -0.5 * plate + plate * j / n;
    const double r = std::hypot(x, y);
    const double z = r < rim ? -d * 0.5 * (1.0 + std::cos(std::numbers::pi * r / rim)) : 0.0;
    return Eigen::Vector3d(x, y, z);
  }, constant(Eigen::Vector3d::UnitZ()));
  return m;
}

TriangleMesh box_with_blind_hole(const Eigen::Vector3d& size, double hd, double depth, double sp) {
  const double a = 0.5 * size.x(), b = 0.5 * size.y(), h = size.z(), rh = 0.5 * hd;
  require(a > 0 && b > 0 && h > 0 && sp > 0, "box_with_blind_hole: sizes must be positive");
  require(rh > 0 && rh < std::min(a, b) && depth > 0 && depth < h, "box_with_blind_hole: hole must fit inside the box");
  TriangleMesh m;
  const int nx = segments(2 * a, sp), ny = segments(2 * b, sp), nz = segments(h, sp);
  // Top face boundary, counterclockwise from corner (a, -b); every corner is a vertex.
  std::vector<Eigen::Vector2d> edge;
  for (int k = 0; k < ny; ++k) edge.emplace_back(a, -b + 2 * b * k / ny);
  for (int k = 0; k < nx; ++k) edge.emplace_back(a - 2 * a * k / nx, b);
  for (int k = 0; k < ny; ++k) edge.emplace_back(-a, b - 2 * b * k / ny);
  for (int k = 0; k < nx; ++k) edge.emplace_back(-a + 2 * a * k / nx, -b);
  const int nb = static_cast<int>(edge.size());
  auto circle = [&](int k) {
    const double t = std::atan2(edge[k % nb].y(), edge[k % nb].x());
    return Eigen::Vector2d(rh * std::cos(t), rh * std::sin(t));
  };
  const int nr = segments(std::min(a, b) - rh, sp);
  add_grid(m, nb, nr, true, [&](int k, int r) {
    const Eigen::Vector2d p = circle(k) + (edge[k % nb] - circle(k)) * (static_cast<double>(r) / nr);
    return Eigen::Vector3d(p.x(), p.y(), h);
  }, constant(Eigen::Vector3d::UnitZ()));
  // Sides: x = ±a, y = ±b.
  add_grid(m, ny, nz, false, [&](int k, int r) { return Eigen::Vector3d(a, -b + 2 * b * k / ny, h * r / nz); }, constant(Eigen::Vector3d::UnitX()));
  add_grid(m, ny, nz, false, [&](int k, int r) { return Eigen::Vector3d(-a, -b + 2 * b * k / ny, h * r / nz); }, constant(-Eigen::Vector3d::UnitX()));
  add_grid(m, nx, nz, false, [&](int k, int r) { return Eigen::Vector3d(a - 2 * a * k / nx, b, h * r / nz); }, constant(Eigen::Vector3d::UnitY()));
  add_grid(m, nx, nz, false, [&](int k, int r) { return Eigen::Vector3d(a - 2 * a * k / nx, -b, h * r / nz); }, constant(-Eigen::Vector3d::UnitY()));
  add_grid(m, nx, ny, false, [&](int i, int j) { return Eigen::Vector3d(a - 2 * a * i / nx, -b + 2 * b * j / ny, 0.0); }, constant(-Eigen::Vector3d::UnitZ()));
  // Hole wall (faces the axis) and floor (faces +Z), on the same angles as the top face's inner ring.
  const int nd = segments(depth, sp), nf = segments(rh, sp);
  add_grid(m, nb, nd, true, [&](int k, int r) {
    const Eigen::Vector2d c = circle(k);
    return Eigen::Vector3d(c.x(), c.y(), h - depth * r / nd);
  }, [](const Eigen::Vector3d& p) { return Eigen::Vector3d(-p.x(), -p.y(), 0.0); });
  add_grid(m, nb, nf, true, [&](int k, int r) {
    const Eigen::Vector2d c = circle(k) * (1.0 - static_cast<double>(r) / nf);
    return Eigen::Vector3d(c.x(), c.y(), h - depth);
  }, constant(Eigen::Vector3d::UnitZ()));
  return weld(m, 1e-6);
}

TriangleMesh cylinder_with_bore(double od, double bd, double height, double sp) {
  const double ro = 0.5 * od, ri = 0.5 * bd;
  require(ro > 0 && ri > 0 && ri < ro && height > 0 && sp > 0, "cylinder_with_bore: need 0 < bore < outer diameter");
  TriangleMesh m;
  const int nt = std::max(12, segments(2 * std::numbers::pi * ro, sp));
  const int nz = segments(height, sp), nr = segments(ro - ri, sp);
  auto ring = [&](double r, int k, double z) {
    const double t = 2 * std::numbers::pi * (k % nt) / nt;
    return Eigen::Vector3d(r * std::cos(t), r * std::sin(t), z);
  };
  add_grid(m, nt, nz, true, [&](int k, int j) { return ring(ro, k, height * j / nz); },
           [](const Eigen::Vector3d& p) { return Eigen::Vector3d(p.x(), p.y(), 0.0); });
  add_grid(m, nt, nz, true, [&](int k, int j) { return ring(ri, k, height * j / nz); },
           [](const Eigen::Vector3d& p) { return Eigen::Vector3d(-p.x(), -p.y(), 0.0); });
  add_grid(m, nt, nr, true, [&](int k, int j) { return ring(ri + (ro - ri) * j / nr, k, height); }, constant(Eigen::Vector3d::UnitZ()));
  add_grid(m, nt, nr, true, [&](int k, int j) { return ring(ri + (ro - ri) * j / nr, k, 0.0); }, constant(-Eigen::Vector3d::UnitZ()));
  return weld(m, 1e-6);
}

std::vector<Eigen::Isometry3d> view_like_poses(int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> el(-0.17, 1.3), az(-std::numbers::pi, std::numbers::pi), dist(200, 400),
      tw(-std::numbers::pi, std::numbers::pi);
  std::vector<Eigen::Isometry3d> out;
  for (int k = 0; k < count; ++k) {
    const double e = el(rng), a = az(rng);
    const Eigen::Vector3d dir(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
    Viewpoint v;
    v.position = Eigen::Vector3d(0, 0, 80) + dist(rng) * dir;
    v.axis = -dir;
    v.twist_rad = tw(rng);
    out.emplace_back(v.transform());
  }
  return out;
}

}  // namespace scancell::planner
