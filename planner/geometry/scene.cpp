#include "planner/geometry/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace scancell::planner {
namespace {

void check_device(RTCDevice device, const char* what) {
  const RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE) throw std::runtime_error(std::string("embree: ") + what + " failed, error " + std::to_string(err));
}

/// The Embree ray of one query (occlusion and intersection streams use the same layout).
void fill_ray(RTCRay& e, const OcclusionRay& r, unsigned id) {
  e.org_x = r.origin.x(); e.org_y = r.origin.y(); e.org_z = r.origin.z();
  // A component under 1e-9 of the direction's largest is rounding (a view turned by a whole quarter turn:
  // cos(π/2) = 6e-17 in its rotation) and is cast as +0: its sign otherwise puts rays that are parallel up to
  // 1e-19 in different octants, and Embree 3's ray streams then missed hits that each ray finds alone (the
  // arm's views of the bored tube: 86 rays in one plan). The direction turns by under 1e-9 rad.
  const float tiny = 1e-9f * std::max({std::abs(r.dir.x()), std::abs(r.dir.y()), std::abs(r.dir.z())});
  auto snapped = [tiny](float c) { return std::abs(c) < tiny ? 0.0f : c; };
  e.dir_x = snapped(r.dir.x()); e.dir_y = snapped(r.dir.y()); e.dir_z = snapped(r.dir.z());
  e.tnear = r.t_near;
  e.tfar = r.t_far;
  e.time = 0.0f;
  e.mask = 0xFFFFFFFFu;
  e.id = id;
  e.flags = 0;
}

}  // namespace

OcclusionScene::OcclusionScene(const TriangleMesh& mesh) {
  device_ = rtcNewDevice(nullptr);
  if (!device_) throw std::runtime_error("embree: cannot create device");
  scene_ = rtcNewScene(device_);
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_MEDIUM);
  // Robust traversal and triangle test: a view turned by a whole quarter turn casts its rays in a plane along a
  // world axis up to rounding (components of ±1e-17 across it), and where that plane holds a line of mesh edges
  // (a CAD part's grid, the rough vertex a view aims at) the fast test let a fifth to a third of such rays
  // slip between the two triangles of each edge: points the rays should shadow read visible, and the
  // virtual scanner saw through the surface (test: scene_test.cpp). Measured: the matrix stage +5-10 %.
  rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                         3 * sizeof(float), mesh.vertices.size()));
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                            3 * sizeof(unsigned), mesh.triangles.size()));
  check_device(device_, "buffer allocation");
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    for (int k = 0; k < 3; ++k) vb[3 * i + k] = static_cast<float>(mesh.vertices[i][k]);
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) ib[3 * i + k] = mesh.triangles[i][k];
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(scene_);
  check_device(device_, "scene build");
}

OcclusionScene::~OcclusionScene() {
  if (scene_) rtcReleaseScene(scene_);
  if (device_) rtcReleaseDevice(device_);
}

void OcclusionScene::occluded(const OcclusionRay* rays, std::size_t count, std::uint8_t* occluded) const {
  constexpr std::size_t kStream = 256;
  RTCRay buf[kStream];
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  for (std::size_t base = 0; base < count; base += kStream) {
    const std::size_t m = std::min(kStream, count - base);
    for (std::size_t i = 0; i < m; ++i) {
      fill_ray(buf[i], rays[base + i], static_cast<unsigned>(i));
    }
    rtcOccluded1M(scene_, &ctx, buf, static_cast<unsigned>(m), sizeof(RTCRay));
    // Embree marks an occluded ray by setting tfar to -inf.
    for (std::size_t i = 0; i < m; ++i) occluded[base + i] = buf[i].tfar < 0.0f ? 1 : 0;
  }
}

bool OcclusionScene::occluded1(const OcclusionRay& ray) const {
  std::uint8_t o = 0;
  occluded(&ray, 1, &o);
  return o != 0;
}

std::optional<Hit> OcclusionScene::first_hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir,
                                             double t_near, double t_far) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh{};
  rh.ray.org_x = static_cast<float>(origin.x());
  rh.ray.org_y = static_cast<float>(origin.y());
  rh.ray.org_z = static_cast<float>(origin.z());
  rh.ray.dir_x = static_cast<float>(unit_dir.x());
  rh.ray.dir_y = static_cast<float>(unit_dir.y());
  rh.ray.dir_z = static_cast<float>(unit_dir.z());
  rh.ray.tnear = static_cast<float>(t_near);
  rh.ray.tfar = static_cast<float>(t_far);
  rh.ray.mask = 0xFFFFFFFFu;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
  return Hit{rh.ray.tfar, rh.hit.primID, Eigen::Vector3d(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), rh.hit.u, rh.hit.v};
}

void OcclusionScene::first_hits(const OcclusionRay* rays, std::size_t count, Hit* hits) const {
  constexpr std::size_t kStream = 256;
  RTCRayHit buf[kStream];
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  // Incoherent, as occluded(): Embree 3's coherent streams missed hits a ray finds alone when the rays' direction
  // has a component of ±1e-19 (a view turned by π/2: a laser plane along an object axis plane), and the virtual
  // scanner lost a fandisk band its rays strike (OcclusionScene.AProfileAlongAnAxisPlaneHitsInABatchAsOneByOne;
  // docs/verification.md).
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  for (std::size_t base = 0; base < count; base += kStream) {
    const std::size_t m = std::min(kStream, count - base);
    for (std::size_t i = 0; i < m; ++i) {
      RTCRayHit& e = buf[i];
      fill_ray(e.ray, rays[base + i], static_cast<unsigned>(i));
      e.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      e.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect1M(scene_, &ctx, buf, static_cast<unsigned>(m), sizeof(RTCRayHit));
    for (std::size_t i = 0; i < m; ++i) {
      const RTCRayHit& e = buf[i];
      Hit& h = hits[base + i];
      if (e.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
        h = Hit{std::numeric_limits<double>::infinity(), kNoHit, Eigen::Vector3d::Zero(), 0.0f, 0.0f};
      } else {
        h = Hit{e.ray.tfar, e.hit.primID, Eigen::Vector3d(e.hit.Ng_x, e.hit.Ng_y, e.hit.Ng_z), e.hit.u, e.hit.v};
      }
    }
  }
}

}  // namespace scancell::planner
