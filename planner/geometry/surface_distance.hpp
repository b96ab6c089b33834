#pragma once
// Distances between two meshes' surfaces, for judging a rough model against the object it stands for (issue
// 9: a fused rough model's Hausdorff distance and normal error against the fine model, in simulation).
// Exact point-to-triangle distances, found through a uniform grid of the target's triangles.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

/// The closest point of a mesh's surface to query points.
class SurfaceIndex {
 public:
  explicit SurfaceIndex(const TriangleMesh& mesh);
  ~SurfaceIndex();
  SurfaceIndex(SurfaceIndex&&) noexcept;
  SurfaceIndex& operator=(SurfaceIndex&&) noexcept;

  struct Closest {
    double distance_mm = 0.0;
    std::uint32_t triangle = 0;
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
  };
  Closest closest(const Eigen::Vector3d& p) const;

 private:
  struct Grid;
  std::unique_ptr<Grid> grid_;
};

/// The closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5).
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

struct SurfaceComparison {
  // From the model's vertices (those selected) to the truth's surface, and from the truth's vertices to the
  // model's surface; the Hausdorff distance is the larger maximum (sampled at the vertices).
  double model_to_truth_max_mm = 0.0, model_to_truth_mean_mm = 0.0;
  double truth_to_model_max_mm = 0.0, truth_to_model_mean_mm = 0.0;
  double hausdorff_mm = 0.0;
  // Angle between each selected model vertex's normal and the normal of the truth triangle closest to it.
  double normal_error_mean_rad = 0.0, normal_error_p95_rad = 0.0;
  std::size_t model_vertices = 0;  // the selected ones
};

/// `model` against `truth`. `select`, if given (one flag per model vertex), limits the model's side to the
/// flagged vertices (a rough model's measured, not hypothetical, part); the truth's side always uses every
/// truth vertex, so the guesses show there.
SurfaceComparison compare_surfaces(const TriangleMesh& model, const TriangleMesh& truth, const std::vector<std::uint8_t>& select = {});

}  // namespace scancell::planner
