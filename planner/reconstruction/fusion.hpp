#pragma once
// The rough model from a rough scan (thesis 1.2.2, 3.1, 3.5.2): range images fused into a truncated signed
// distance volume (Curless-Levoy style: a weighted running average of the distance along each laser ray
// within ±τ of its sample; voxels a ray passed through on its way are carved empty), and a closed surface
// extracted from it with marching tetrahedra (each grid cube cut into six tetrahedra about its main diagonal;
// no ambiguous case, so the surface is an oriented closed 2-manifold the decimator takes whole).
//
// What no ray has seen but lies behind a measured surface (the underside on the plate, deep recesses, the
// interior) counts as material: the surface closes conservatively around it, and every vertex on such a
// boundary is marked hypothetical, so the planner knows that part of the rough model is a guess. "Behind"
// needs `occluding_views` views to agree, so the shadow one view casts past the object's silhouette, which
// no other view happened to cross, is not mistaken for material. Space no view looked into is left empty;
// below `floor_z_mm` (the turntable plate's top) is never the object.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/geometry/mesh.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

struct FusionOptions {
  double voxel_mm = 1.5;
  double truncation_voxels = 3.0;  // τ = truncation_voxels · voxel
  int carve_stride = 2;            // carve free space (and mark occluded space) along every n-th ray per row and column
  double floor_z_mm = -1e9;        // nothing of the object below this (the plate's top, object frame)
  int occluding_views = 3;         // unseen space is material when at least this many views saw it hidden
};

struct FusedModel {
  TriangleMesh mesh;                      // closed where the volume is closed, mm, object frame
  std::vector<std::uint8_t> hypothetical; // per vertex: 1 where the surface bounds unseen space, not a measurement
  std::size_t observed_voxels = 0, carved_voxels = 0;
  std::size_t dropped_pieces_vertices = 0;  // vertices of closed pieces with no measured point, removed
};

class TsdfVolume {
 public:
  /// `bounds_mm`: the region to model (the object's bounding box with a margin), object frame.
  TsdfVolume(const Eigen::AlignedBox3d& bounds_mm, const FusionOptions& options = {});
  /// Fuses one range image (samples in the object frame, laser origins from the image's pose).
  void integrate(const RangeImage& image);
  FusedModel extract() const;
  double voxel_mm() const { return voxel_; }

 private:
  std::size_t at(long i, long j, long k) const {
    return (static_cast<std::size_t>(k) * ny_ + static_cast<std::size_t>(j)) * nx_ + static_cast<std::size_t>(i);
  }
  bool inside(long i, long j, long k) const { return i >= 0 && j >= 0 && k >= 0 && i < nx_ && j < ny_ && k < nz_; }
  Eigen::Vector3d centre(long i, long j, long k) const;
  /// The field the extraction contours: the TSDF where observed, +τ where carved, -τ where unseen.
  float field(std::size_t v) const;

  Eigen::Vector3d origin_;  // centre of voxel (0, 0, 0)
  double voxel_ = 1.5, tau_ = 4.5;
  long nx_ = 0, ny_ = 0, nz_ = 0;
  int carve_stride_ = 2;
  double floor_z_ = -1e9;
  std::vector<float> tsdf_, weight_;
  int occluding_views_ = 3;
  std::uint16_t view_ = 0;                  // images integrated so far
  std::vector<std::uint8_t> carved_, behind_;  // behind_: how many views saw the voxel hidden (saturating)
  std::vector<std::uint16_t> last_view_;
};

}  // namespace scancell::planner
