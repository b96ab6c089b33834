#pragma once
// Embree scene of a triangle mesh for visibility (occlusion) and first-hit queries.
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <embree3/rtcore.h>

#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

/// Rays cast from just off a surface (the surface point moved by a ray offset along its normal) start this
/// share of that offset further along their way. The scene is robust (watertight at edges), and so it reports
/// a second surface through the offset origin as a hit at t = 0: on a mesh whose faces are not welded, the
/// foot of a wall under a floor row at its edge, which a ray leaving the wall sees nothing of (a square
/// cavity's floor rows read unmeasurable). Skipping a tenth of the offset passes such touches, as the fast
/// test did, and nothing the offset itself would not.
inline constexpr double kOffSurfaceStart = 0.1;

/// One occlusion query: is the open segment origin -> origin + dir * t_far free of surface?
struct OcclusionRay {
  Eigen::Vector3f origin;
  Eigen::Vector3f dir;  // need not be unit; t is in units of |dir|
  float t_near = 0.0f;
  float t_far = 0.0f;
};

struct Hit {
  double t;                  // distance along the (unit) ray
  std::uint32_t triangle;    // primitive id
  Eigen::Vector3d geometric_normal;  // unnormalised, as Embree reports it (winding order)
  float u = 0.0f, v = 0.0f;  // barycentrics: point = (1-u-v)·v0 + u·v1 + v·v2
};

/// Triangle id of a ray that hit nothing.
inline constexpr std::uint32_t kNoHit = 0xFFFFFFFFu;

class OcclusionScene {
 public:
  explicit OcclusionScene(const TriangleMesh& mesh);
  ~OcclusionScene();
  OcclusionScene(const OcclusionScene&) = delete;
  OcclusionScene& operator=(const OcclusionScene&) = delete;

  /// Streams the rays through rtcOccluded1M (incoherent); occluded[i] = 1 when something blocks ray i.
  /// Thread-safe: many threads may query one scene.
  void occluded(const OcclusionRay* rays, std::size_t count, std::uint8_t* occluded) const;

  bool occluded1(const OcclusionRay& ray) const;

  /// First hits of a batch of rays (rtcIntersect1M, coherent: one laser profile or one image row at a time).
  /// hits[i].triangle == kNoHit when ray i hits nothing in [t_near, t_far]; t is in units of |dir|.
  void first_hits(const OcclusionRay* rays, std::size_t count, Hit* hits) const;

  /// First hit along a unit direction within [t_near, t_far], if any.
  std::optional<Hit> first_hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double t_near,
                               double t_far) const;

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

}  // namespace scancell::planner
