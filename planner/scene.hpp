#pragma once
// Embree scene of a triangle mesh for visibility (occlusion) and first-hit queries.
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <embree3/rtcore.h>

#include "planner/mesh.hpp"

namespace scancell::planner {

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
};

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

  /// First hit along a unit direction within [t_near, t_far], if any.
  std::optional<Hit> first_hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double t_near,
                               double t_far) const;

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

}  // namespace scancell::planner
