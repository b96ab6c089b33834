#include "planner/reconstruction/inspection.hpp"

#include <algorithm>
#include <cmath>

#include "common/errors.hpp"
#include "planner/geometry/surface_distance.hpp"

namespace scancell::planner {

DeviationStats signed_deviation(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& reference,
                                double tolerance_mm, std::vector<double>* per_point) {
  if (reference.triangles.empty()) throw DataError("inspection: the reference surface has no triangles");
  DeviationStats s;
  s.points = points.size();
  if (per_point) per_point->assign(points.size(), 0.0);
  if (points.empty()) return s;
  const SurfaceIndex index(reference);
  std::vector<double> magnitude(points.size());
  double sum = 0.0, sum_sq = 0.0;
  std::size_t within = 0;
  for (std::size_t k = 0; k < points.size(); ++k) {
    const SurfaceIndex::Closest c = index.closest(points[k]);
    const Triangle& t = reference.triangles[c.triangle];
    const Eigen::Vector3d n =
        (reference.vertices[t[1]] - reference.vertices[t[0]]).cross(reference.vertices[t[2]] - reference.vertices[t[0]]);
    const double d = (points[k] - c.point).dot(n) < 0.0 ? -c.distance_mm : c.distance_mm;
    if (per_point) (*per_point)[k] = d;
    sum += d;
    sum_sq += d * d;
    magnitude[k] = std::abs(d);
    within += magnitude[k] <= tolerance_mm;
  }
  const double n = static_cast<double>(points.size());
  s.mean_mm = sum / n;
  s.rms_mm = std::sqrt(sum_sq / n);
  s.within_tolerance = static_cast<double>(within) / n;
  // The 95th percentile by rank: the smallest value at least 95 % of the points do not exceed.
  const std::size_t rank = static_cast<std::size_t>(std::ceil(0.95 * n)) - 1;
  std::nth_element(magnitude.begin(), magnitude.begin() + static_cast<std::ptrdiff_t>(rank), magnitude.end());
  s.p95_abs_mm = magnitude[rank];
  s.max_abs_mm = *std::max_element(magnitude.begin(), magnitude.end());
  return s;
}

}  // namespace scancell::planner
