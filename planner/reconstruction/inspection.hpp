#pragma once
// Inspection against a reference surface (issue 19): how far the job's cloud and model lie from the object
// they stand for, signed along the reference's outward normal (+ outside, − inside), the way a metrology
// report states deviation.
#include <vector>

#include <Eigen/Core>

#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

struct DeviationStats {
  std::size_t points = 0;
  double mean_mm = 0.0;          // signed mean: a bias outwards (+) or inwards (−)
  double rms_mm = 0.0;           // of the signed deviation
  double p95_abs_mm = 0.0;       // 95th percentile of |deviation|
  double max_abs_mm = 0.0;
  double within_tolerance = 0.0; // share of points with |deviation| ≤ the tolerance given
};

/// Signed distance of each point to `reference`'s surface (closest point, sign from that triangle's outward
/// normal), summarised; `per_point` receives the signed values when given. Throws DataError for an empty
/// reference.
DeviationStats signed_deviation(const std::vector<Eigen::Vector3d>& points, const TriangleMesh& reference,
                                double tolerance_mm, std::vector<double>* per_point = nullptr);

}  // namespace scancell::planner
