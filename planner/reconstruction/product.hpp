#pragma once
// What a scan job hands over (issue 19), from the range images it measured: the registered cloud of every
// spec-compliant sample and the surface fused from it. Plain functions of the images: the daemon writes
// them durably per job (daemon/job_product), `scancell fuse` offline from range-image files.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "planner/config.hpp"
#include "planner/reconstruction/surface_mesh.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

/// A measured view that counts toward the product (its registration did not fail).
struct ProductView {
  RangeImage image;
  int view = 0, round = 0;  // index within its round's plan; round (0, 1, ...)
};

struct CloudSummary {
  std::size_t points = 0;     // samples written (all spec-compliant ones, or one per cell when decimated)
  std::size_t compliant = 0;  // spec-compliant samples in the views
  std::size_t views = 0;   // views they come from
  std::vector<Eigen::Vector3d> positions, normals;  // the samples written (object frame, mm), when asked for
};

/// The cloud as a binary little-endian PLY: one vertex per sample that meets the spec (σz ≤ precision, local
/// density ≥ density, thesis eq. 3.4/3.8) in the object frame, as registered: x y z (mm), nx ny nz (unit
/// normal from its image neighbours, towards the scanner; 0 0 0 where a neighbour is missing), sigma_z_mm,
/// view, round. `job` is named in a comment (0: none). Fills `summary` (with every compliant sample, for the
/// model, when `keep_samples`). `spacing_mm` > 0 writes one sample per cube of that side (the first in view
/// order: deterministic), and says so in a comment; 0 keeps all.
std::string cloud_ply(const std::vector<ProductView>& views, std::int64_t job, const ModelSpec& spec,
                      CloudSummary& summary, bool keep_samples = false, double spacing_mm = 0.0);

struct ModelSummary {
  std::size_t vertices = 0, triangles = 0, boundary_edges = 0;  // boundary: edges of the holes left open
  double voxel_mm = 0.0;
  std::vector<Eigen::Vector3d> positions;  // the model's vertices (object frame, mm)
};

/// The surface fused from a cloud kept with its samples, at a voxel of half the spec's sample spacing,
/// 1/(2√ρ) (mesh_from_oriented_points: OpenVDB sparse field, VolumeToMesh), open where nothing was
/// measured. DataError when the cloud holds no samples.
SurfaceMesh fuse_model(const CloudSummary& cloud, const ModelSpec& spec, ModelSummary& summary);

}  // namespace scancell::planner
