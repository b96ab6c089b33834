#pragma once
// The object's surface from its registered, spec-compliant samples (the model of the thesis' reconstruction
// cycle, fig. 1.2): a signed distance field in a sparse volume (OpenVDB), each voxel near the samples taking
// the Gaussian-weighted mean of n·(x − p) over the samples p (normal n) around it, and its zero crossing
// meshed (OpenVDB VolumeToMesh). Only where samples are: a surface never measured stays a hole, nothing is
// invented to close it.
#include <vector>

#include <Eigen/Core>

#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

struct SurfaceMeshOptions {
  double voxel_mm = 0.35;     // grid spacing; about half the spec's sample spacing 1/√ρ
  double radius_voxels = 3.0; // a sample informs voxels this far from it (Gaussian σ = one voxel)
  double min_weight = 0.05;   // a voxel with less summed weight has no value (too far from every sample)
};

struct SurfaceMesh {
  TriangleMesh mesh;                 // mm, triangles wound with their normals out of the object
  std::vector<float> support;        // per vertex: summed sample weight there (how well measured)
  std::size_t active_voxels = 0;     // voxels of the sparse field (memory: ~ this × 12 bytes)
};

/// `points` and unit `normals` (towards the scanner; zero normals are skipped) in mm.
SurfaceMesh mesh_from_oriented_points(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
                                      const SurfaceMeshOptions& options = {});

/// Binary little-endian PLY bytes: vertices (x y z mm, float support), faces (uchar count, int indices).
std::string surface_ply(const SurfaceMesh& surface);

}  // namespace scancell::planner
