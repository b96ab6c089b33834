#pragma once
// The rough model (thesis 3.1, ch. 5): the decimated mesh whose vertices are the rows of the measurability
// matrix. Rows are stored in Morton (Z-curve) order so that neighbouring rows are neighbours in space, which
// makes frustum culling by blocks effective and occlusion rays coherent.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "planner/core/rough_model_limits.hpp"
#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

struct RoughModel {
  std::vector<Eigen::Vector3d> points;   // s_i, mm, Morton order
  std::vector<Eigen::Vector3d> normals;  // unit, area-weighted vertex normals
  std::vector<double> area_mm2;          // each vertex's share (1/3) of its triangles' area
  std::vector<Triangle> triangles;
  std::vector<int> segment;              // per row: surface patch label (thesis 3.5.1), -1 none; empty if unsegmented
  std::vector<std::uint8_t> hypothetical;  // per row: 1 where a rough scan closed unseen space (a guess); empty if none
  double total_area_mm2 = 0.0;
  double mean_edge_mm = 0.0;

  std::size_t size() const { return points.size(); }
  TriangleMesh mesh() const { return {points, triangles}; }
};

struct RoughModelOptions {
  std::optional<std::size_t> target_vertices;  // --rough-vertices
  std::optional<double> rho_rel;                // --rho-rel: log2(rough density / input density), thesis 5.3
  double normal_noise_mm = 0.0;                 // σ_rm: Gaussian displacement along the normal, thesis 5.4
  /// The error the mesh itself already carries along its normal (σ, mm), not added: a rough scan's fused
  /// surface (the daemon's jobs.fused_model_sigma_mm). The plan treats it as it treats σ_rm
  /// (rough_model_carries_error).
  double surface_error_mm = 0.0;
  std::uint64_t seed = 1;
  /// Optional segmentation: one label per input vertex (>= 0, or -1 for none). Decimation keeps surviving
  /// vertices where they were, so labels follow them exactly.
  std::vector<int> vertex_labels;
  /// Optional: 1 per input vertex the rough scan only guessed (planner/fusion.hpp); carried like the labels.
  std::vector<std::uint8_t> vertex_hypothetical;
};

/// Whether the rough model is known to stand off the true surface: simulated noise (σ_rm) or a mesh that
/// carries its own error (a rough scan). The planner then keeps its margins against that error everywhere.
inline bool rough_model_carries_error(const RoughModelOptions& o) { return o.normal_noise_mm > 0.0 || o.surface_error_mm > 0.0; }

struct RoughModelReport {
  std::size_t input_vertices = 0;
  std::size_t output_vertices = 0;
  std::size_t faces_rejected_by_decimator = 0;  // non-manifold faces OpenMesh could not add
  bool decimated = false;
};

/// From this many vertices (and 4× the target) a mesh is decimated in two halves at once (decimate()).
inline constexpr std::size_t kDecimateInHalvesMinVertices = 20000;

/// Quadric decimation (OpenMesh Decimater, ModQuadric) to at most target_vertices vertices. A mesh of
/// kDecimateInHalvesMinVertices or more (and at least 4× the target) is cut in two by its faces' median
/// along its longest side; the halves are decimated at once, the vertices they share kept, and then the band
/// along the cut: about half the time on two cores, the same result for any thread count.
TriangleMesh decimate(const TriangleMesh& mesh, std::size_t target_vertices, std::size_t* faces_rejected = nullptr);

/// Builds the rough model: optional decimation and normal noise, then normals, areas and Morton order.
RoughModel build_rough_model(TriangleMesh mesh, const RoughModelOptions& options, RoughModelReport* report = nullptr);

/// Normals, areas and Morton ordering of an already final mesh (no decimation, no noise); `labels` and
/// `hypothetical`, if given, one per mesh vertex, become the rows' segments and hypothetical flags.
RoughModel make_rough_model(const TriangleMesh& mesh, const std::vector<int>& labels = {},
                            const std::vector<std::uint8_t>& hypothetical = {});

/// Area-weighted unit vertex normals (unnormalised face normals summed; their length is twice the area).
std::vector<Eigen::Vector3d> area_weighted_normals(const TriangleMesh& mesh);

/// Rows on a crease (issue 15): some adjacent triangle's normal lies more than `min_angle_rad` from the row's
/// own normal (and every row without a normal). There the vertex normal is a bisector no surface has: a box's
/// edge or corner, a hole's rim, the floor of a pocket where it meets the wall. Ascending.
std::vector<std::uint32_t> crease_rows(const RoughModel& rough, double min_angle_rad);

}  // namespace scancell::planner
