#include "planner/geometry/surface_distance.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

#include "common/errors.hpp"
#include "planner/core/rough_model.hpp"

namespace scancell::planner {

Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// Triangles bucketed by the cells their bounding boxes touch. A query searches shells of cells outwards and
// stops once the best distance is within the shells searched: nothing farther out can be closer.
struct SurfaceIndex::Grid {
  TriangleMesh copy;
  Eigen::Vector3d lo;
  double cell = 1.0;
  Eigen::Vector3i n;
  std::vector<std::vector<std::uint32_t>> cells;
  std::size_t index(int i, int j, int k) const {
    return (static_cast<std::size_t>(k) * static_cast<std::size_t>(n.y()) + static_cast<std::size_t>(j)) * static_cast<std::size_t>(n.x()) +
           static_cast<std::size_t>(i);
  }
  Eigen::Vector3i cell_of(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d g = (p - lo) / cell;
    return Eigen::Vector3i(std::clamp(static_cast<int>(std::floor(g.x())), 0, n.x() - 1), std::clamp(static_cast<int>(std::floor(g.y())), 0, n.y() - 1),
                           std::clamp(static_cast<int>(std::floor(g.z())), 0, n.z() - 1));
  }
};

SurfaceIndex::SurfaceIndex(const TriangleMesh& mesh) : grid_(std::make_unique<Grid>()) {
  if (mesh.triangles.empty()) throw DataError("surface distance: a mesh without triangles");
  Grid& g = *grid_;
  g.copy = mesh;
  Eigen::AlignedBox3d box;
  for (const auto& v : g.copy.vertices) box.extend(v);
  // A few triangles a cell on a closed surface: cells of ~2 mean edge lengths, at most 64 a side.
  double edge = 0.0;
  for (const auto& t : g.copy.triangles) edge += (g.copy.vertices[t[1]] - g.copy.vertices[t[0]]).norm();
  edge /= static_cast<double>(g.copy.triangles.size());
  g.cell = std::max({2.0 * edge, box.sizes().maxCoeff() / 64.0, 1e-6});
  g.lo = box.min();
  g.n = ((box.sizes() / g.cell).array().floor().cast<int>() + 1).matrix();
  g.cells.resize(static_cast<std::size_t>(g.n.x()) * g.n.y() * g.n.z());
  for (std::uint32_t t = 0; t < g.copy.triangles.size(); ++t) {
    Eigen::AlignedBox3d tb;
    for (auto v : g.copy.triangles[t]) tb.extend(g.copy.vertices[v]);
    const Eigen::Vector3i a = g.cell_of(tb.min()), b = g.cell_of(tb.max());
    for (int k = a.z(); k <= b.z(); ++k)
      for (int j = a.y(); j <= b.y(); ++j)
        for (int i = a.x(); i <= b.x(); ++i) g.cells[g.index(i, j, k)].push_back(t);
  }
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

SurfaceIndex::Closest SurfaceIndex::closest(const Eigen::Vector3d& p) const {
  const Grid& g = *grid_;
  Closest best;
  best.distance_mm = std::numeric_limits<double>::infinity();
  const Eigen::Vector3i c = g.cell_of(p);  // clamped into the grid when p is outside it
  const int most = g.n.maxCoeff();
  for (int r = 0; r <= most; ++r) {
    for (int k = c.z() - r; k <= c.z() + r; ++k)
      for (int j = c.y() - r; j <= c.y() + r; ++j)
        for (int i = c.x() - r; i <= c.x() + r; ++i) {
          if (std::max({std::abs(i - c.x()), std::abs(j - c.y()), std::abs(k - c.z())}) != r) continue;  // the shell only
          if (i < 0 || j < 0 || k < 0 || i >= g.n.x() || j >= g.n.y() || k >= g.n.z()) continue;
          for (auto t : g.cells[g.index(i, j, k)]) {
            const auto& tri = g.copy.triangles[t];
            const Eigen::Vector3d q = closest_on_triangle(p, g.copy.vertices[tri[0]], g.copy.vertices[tri[1]], g.copy.vertices[tri[2]]);
            const double d = (q - p).norm();
            if (d < best.distance_mm) best = {d, t, q};
          }
        }
    // Every cell beyond shell r is at least r cell widths from p, inside the grid or out.
    if (best.distance_mm <= r * g.cell) break;
  }
  return best;
}

namespace {

Eigen::Vector3d triangle_normal(const TriangleMesh& m, std::uint32_t t) {
  const auto& tri = m.triangles[t];
  return (m.vertices[tri[1]] - m.vertices[tri[0]]).cross(m.vertices[tri[2]] - m.vertices[tri[0]]).normalized();
}

}  // namespace

SurfaceComparison compare_surfaces(const TriangleMesh& model, const TriangleMesh& truth, const std::vector<std::uint8_t>& select) {
  if (!select.empty() && select.size() != model.vertices.size())
    throw DataError("surface comparison: " + std::to_string(select.size()) + " flags for " + std::to_string(model.vertices.size()) + " vertices");
  SurfaceComparison out;
  const SurfaceIndex to_truth(truth), to_model(model);
  const std::vector<Eigen::Vector3d> normals = area_weighted_normals(model);
  std::vector<double> angles;
  double sum = 0.0;
  for (std::size_t v = 0; v < model.vertices.size(); ++v) {
    if (!select.empty() && !select[v]) continue;
    const auto c = to_truth.closest(model.vertices[v]);
    out.model_to_truth_max_mm = std::max(out.model_to_truth_max_mm, c.distance_mm);
    sum += c.distance_mm;
    angles.push_back(std::acos(std::clamp(normals[v].dot(triangle_normal(truth, c.triangle)), -1.0, 1.0)));
  }
  out.model_vertices = angles.size();
  if (!angles.empty()) {
    out.model_to_truth_mean_mm = sum / static_cast<double>(angles.size());
    double a = 0.0;
    for (double x : angles) a += x;
    out.normal_error_mean_rad = a / static_cast<double>(angles.size());
    const auto k = static_cast<std::ptrdiff_t>(0.95 * static_cast<double>(angles.size() - 1));
    std::nth_element(angles.begin(), angles.begin() + k, angles.end());
    out.normal_error_p95_rad = angles[static_cast<std::size_t>(k)];
  }
  sum = 0.0;
  for (const auto& v : truth.vertices) {
    const double d = to_model.closest(v).distance_mm;
    out.truth_to_model_max_mm = std::max(out.truth_to_model_max_mm, d);
    sum += d;
  }
  out.truth_to_model_mean_mm = truth.vertices.empty() ? 0.0 : sum / static_cast<double>(truth.vertices.size());
  out.hausdorff_mm = std::max(out.model_to_truth_max_mm, out.truth_to_model_max_mm);
  return out;
}

}  // namespace scancell::planner
