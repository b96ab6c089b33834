#include "planner/reconstruction/fusion.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "common/errors.hpp"

namespace scancell::planner {

TsdfVolume::TsdfVolume(const Eigen::AlignedBox3d& b, const FusionOptions& o)
    : voxel_(o.voxel_mm), tau_(o.truncation_voxels * o.voxel_mm), carve_stride_(std::max(1, o.carve_stride)),
      floor_z_(o.floor_z_mm), occluding_views_(std::max(1, o.occluding_views)) {
  if (!(o.voxel_mm > 0.0) || !(o.truncation_voxels >= 1.0)) throw ConfigError("fusion: voxel_mm must be > 0, truncation_voxels >= 1");
  if (b.isEmpty()) throw DataError("fusion: empty bounds");
  const Eigen::Vector3d size = b.sizes();
  nx_ = static_cast<long>(std::ceil(size.x() / voxel_)) + 3;
  ny_ = static_cast<long>(std::ceil(size.y() / voxel_)) + 3;
  nz_ = static_cast<long>(std::ceil(size.z() / voxel_)) + 3;
  const double voxels = static_cast<double>(nx_) * ny_ * nz_;
  if (voxels > 4e8) throw ConfigError("fusion: " + std::to_string(static_cast<long long>(voxels)) + " voxels; use a coarser voxel_mm");
  origin_ = b.min() - Eigen::Vector3d::Constant(voxel_);
  tsdf_.assign(static_cast<std::size_t>(voxels), 0.0f);
  weight_.assign(static_cast<std::size_t>(voxels), 0.0f);
  carved_.assign(static_cast<std::size_t>(voxels), 0);
  behind_.assign(static_cast<std::size_t>(voxels), 0);
  last_view_.assign(static_cast<std::size_t>(voxels), 0);
}

Eigen::Vector3d TsdfVolume::centre(long i, long j, long k) const {
  return origin_ + voxel_ * Eigen::Vector3d(static_cast<double>(i), static_cast<double>(j), static_cast<double>(k));
}

void TsdfVolume::integrate(const RangeImage& img) {
  const Eigen::Isometry3d& pose = img.pose.camera_to_object;
  ++view_;
  for (int r = 0; r < img.rows; ++r)
    for (int c = 0; c < img.columns; ++c) {
      const RangeSample& s = img.at(c, r);
      if (!s.valid()) continue;
      const Eigen::Vector3d p = s.object_mm.cast<double>();
      // The laser of this sample's profile: (0, y, 0) in the view frame, y the sample's own (line scan).
      const Eigen::Vector3d laser = pose * Eigen::Vector3d(0.0, img.kind == SensorKind::line_scan ? s.camera_mm.y() : 0.0, 0.0);
      Eigen::Vector3d u = p - laser;
      const double range = u.norm();
      if (!(range > tau_)) continue;
      u /= range;
      // Distance band ±τ about the sample: running weighted average of the signed distance along the ray.
      const double step = 0.5 * voxel_;
      for (double t = -tau_; t <= tau_; t += step) {
        const Eigen::Vector3d q = p + t * u;
        const Eigen::Vector3d g = (q - origin_) / voxel_;
        const long i = std::lround(g.x()), j = std::lround(g.y()), k = std::lround(g.z());
        if (!inside(i, j, k)) continue;
        const double sdf = (p - centre(i, j, k)).dot(u);  // > 0 in front of the surface (towards the laser)
        if (sdf < -tau_) continue;
        const float d = static_cast<float>(std::clamp(sdf, -tau_, tau_) / tau_);
        const std::size_t v = at(i, j, k);
        tsdf_[v] = (tsdf_[v] * weight_[v] + d) / (weight_[v] + 1.0f);
        weight_[v] += 1.0f;
      }
      // Free space the ray crossed before the band; occluded space behind it, out of the volume.
      if (r % carve_stride_ || c % carve_stride_) continue;
      for (double t = 0.0; t < range - tau_; t += 0.5 * voxel_) {
        const Eigen::Vector3d g = (laser + t * u - origin_) / voxel_;
        const long i = std::lround(g.x()), j = std::lround(g.y()), k = std::lround(g.z());
        if (inside(i, j, k)) carved_[at(i, j, k)] = 1;
      }
      for (double t = range + tau_;; t += 0.5 * voxel_) {
        const Eigen::Vector3d g = (laser + t * u - origin_) / voxel_;
        const long i = std::lround(g.x()), j = std::lround(g.y()), k = std::lround(g.z());
        if (!inside(i, j, k)) break;
        const std::size_t v = at(i, j, k);
        if (last_view_[v] != view_) {  // once per view
          last_view_[v] = view_;
          if (behind_[v] < 255) ++behind_[v];
        }
      }
    }
}

float TsdfVolume::field(std::size_t v) const {
  if (weight_[v] > 0.0f) return tsdf_[v];
  if (carved_[v]) return 1.0f;
  return behind_[v] >= occluding_views_ ? -1.0f : 1.0f;  // unseen behind surfaces: material; else empty
}

namespace {

/// A grid corner and the field's value there.
struct Corner {
  long i, j, k;
  float f;
};

/// One tetrahedron of a cube (corners `tet` of `c`) cut by the zero level: one triangle when one corner
/// differs from the other three, two (a quad) when two and two, none when all agree. `emit` takes the edges
/// (e0[n], e1[n]) each triangle vertex lies on and the outward direction (material to free space).
template <class Position, class Emit>
void march_tetrahedron(const std::array<Corner, 8>& c, const std::array<int, 4>& tet, Position position, Emit emit) {
  std::array<const Corner*, 4> in{}, outside{};
  int ni = 0, no = 0;
  for (int n : tet) {
    const Corner* cn = &c[static_cast<std::size_t>(n)];
    if (cn->f < 0.0f) in[static_cast<std::size_t>(ni++)] = cn;
    else outside[static_cast<std::size_t>(no++)] = cn;
  }
  if (ni == 0 || no == 0) return;
  Eigen::Vector3d mi = Eigen::Vector3d::Zero(), mo = Eigen::Vector3d::Zero();
  for (int n = 0; n < ni; ++n) mi += position(*in[static_cast<std::size_t>(n)]) / ni;
  for (int n = 0; n < no; ++n) mo += position(*outside[static_cast<std::size_t>(n)]) / no;
  const Eigen::Vector3d outward = mo - mi;
  if (ni == 1) {
    emit({in[0], in[0], in[0]}, {outside[0], outside[1], outside[2]}, outward);
  } else if (no == 1) {
    emit({in[0], in[1], in[2]}, {outside[0], outside[0], outside[0]}, outward);
  } else {  // two and two: the quad a-c, a-d, b-d, b-c, as two triangles
    const Corner *a = in[0], *b = in[1], *cc = outside[0], *d = outside[1];
    emit({a, a, b}, {cc, d, d}, outward);
    emit({a, b, b}, {cc, d, cc}, outward);
  }
}

/// A closed piece of surface without a single measured point on it (a shadow several views agree on, far
/// from the object; a bubble inside it) is not the object: only the pieces something was measured on.
FusedModel keep_measured_pieces(const FusedModel& out) {
  const std::size_t nv = out.mesh.vertices.size();
  std::vector<std::uint32_t> parent(nv);
  for (std::uint32_t v = 0; v < nv; ++v) parent[v] = v;
  auto find = [&](std::uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : out.mesh.triangles) {
    parent[find(t[1])] = find(t[0]);
    parent[find(t[2])] = find(t[0]);
  }
  std::vector<std::uint8_t> real(nv, 0);
  for (std::uint32_t v = 0; v < nv; ++v)
    if (!out.hypothetical[v]) real[find(v)] = 1;
  std::vector<std::uint32_t> remap(nv, UINT32_MAX);
  FusedModel kept;
  kept.observed_voxels = out.observed_voxels;
  kept.carved_voxels = out.carved_voxels;
  for (std::uint32_t v = 0; v < nv; ++v)
    if (real[find(v)]) {
      remap[v] = static_cast<std::uint32_t>(kept.mesh.vertices.size());
      kept.mesh.vertices.push_back(out.mesh.vertices[v]);
      kept.hypothetical.push_back(out.hypothetical[v]);
    }
  for (const auto& t : out.mesh.triangles)
    if (remap[t[0]] != UINT32_MAX) kept.mesh.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  kept.dropped_pieces_vertices = nv - kept.mesh.vertices.size();
  return kept;
}

}  // namespace

FusedModel TsdfVolume::extract() const {
  FusedModel out;
  for (std::size_t v = 0; v < weight_.size(); ++v) {
    out.observed_voxels += weight_[v] > 0.0f;
    out.carved_voxels += carved_[v] != 0;
  }
  // The volume's border counts as outside, so the surface closes inside it.
  auto below_floor = [&](long k) { return origin_.z() + voxel_ * static_cast<double>(k) < floor_z_; };
  auto value = [&](long i, long j, long k) -> float {
    if (i <= 0 || j <= 0 || k <= 0 || i >= nx_ - 1 || j >= ny_ - 1 || k >= nz_ - 1 || below_floor(k)) return 1.0f;
    return field(at(i, j, k));
  };
  // A corner that is material only by the conservative guess makes the vertices on its edges hypothetical;
  // so does one that is outside only because the volume's border or the table cuts it there (the underside
  // of an object standing on the plate is that cut, not a measurement, however close to a seen wall).
  auto guessed = [&](long i, long j, long k) {
    if (i <= 0 || j <= 0 || k <= 0 || i >= nx_ - 1 || j >= ny_ - 1 || k >= nz_ - 1 || below_floor(k)) return true;
    const std::size_t v = at(i, j, k);
    return weight_[v] == 0.0f && !carved_[v] && behind_[v] >= occluding_views_;
  };
  // Marching tetrahedra on the Kuhn triangulation of the grid (every cube cut into the six tetrahedra about
  // its main diagonal; neighbouring cubes cut their shared face along the same diagonal). Unlike surface nets
  // or plain marching cubes it has no ambiguous case, so the surface is a closed 2-manifold wherever the
  // volume is closed: the rough-model decimator takes every face. One vertex per grid edge (axis, face or
  // body diagonal) the surface crosses, shared by every tetrahedron on that edge.
  std::unordered_map<std::uint64_t, std::uint32_t> vertex_of;
  auto edge_vertex = [&](const Corner& a, const Corner& b) -> std::uint32_t {
    const std::uint64_t ia = at(a.i, a.j, a.k), ib = at(b.i, b.j, b.k);
    const std::uint64_t key = std::min(ia, ib) << 32 | std::max(ia, ib);
    const auto it = vertex_of.find(key);
    if (it != vertex_of.end()) return it->second;
    // Kept off the corners, so no two vertices coincide and no triangle is degenerate.
    const double t = std::clamp(static_cast<double>(a.f) / static_cast<double>(a.f - b.f), 1e-3, 1.0 - 1e-3);
    const auto id = static_cast<std::uint32_t>(out.mesh.vertices.size());
    out.mesh.vertices.push_back((1.0 - t) * centre(a.i, a.j, a.k) + t * centre(b.i, b.j, b.k));
    out.hypothetical.push_back(guessed(a.i, a.j, a.k) || guessed(b.i, b.j, b.k));
    vertex_of.emplace(key, id);
    return id;
  };
  auto position = [&](const Corner& c) { return centre(c.i, c.j, c.k); };
  // Wound so the normal points from material (negative) to free space (positive). The winding is decided on
  // the edge midpoints, where the triangle is never degenerate; the interpolated vertices lie on the same
  // edges, on the same side of every corner, so the orientation carries over.
  auto emit = [&](const std::array<const Corner*, 3>& e0, const std::array<const Corner*, 3>& e1, const Eigen::Vector3d& outward) {
    std::array<Eigen::Vector3d, 3> mid;
    for (int n = 0; n < 3; ++n) mid[static_cast<std::size_t>(n)] = 0.5 * (position(*e0[static_cast<std::size_t>(n)]) + position(*e1[static_cast<std::size_t>(n)]));
    std::array<std::uint32_t, 3> t;
    for (int n = 0; n < 3; ++n) t[static_cast<std::size_t>(n)] = edge_vertex(*e0[static_cast<std::size_t>(n)], *e1[static_cast<std::size_t>(n)]);
    if ((mid[1] - mid[0]).cross(mid[2] - mid[0]).dot(outward) < 0.0) std::swap(t[1], t[2]);
    out.mesh.triangles.push_back({t[0], t[1], t[2]});
  };
  // Corner n of a cube at offset (n & 1, n >> 1 & 1, n >> 2 & 1); the six tetrahedra 0 → 7 by axis order.
  static constexpr std::array<std::array<int, 4>, 6> kuhn = {{{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};
  for (long k = 0; k + 1 < nz_; ++k)
    for (long j = 0; j + 1 < ny_; ++j)
      for (long i = 0; i + 1 < nx_; ++i) {
        std::array<Corner, 8> c;
        int material = 0;
        for (int n = 0; n < 8; ++n) {
          Corner& cn = c[static_cast<std::size_t>(n)];
          cn = {i + (n & 1), j + (n >> 1 & 1), k + (n >> 2 & 1), 0.0f};
          cn.f = value(cn.i, cn.j, cn.k);
          material += cn.f < 0.0f;
        }
        if (material == 0 || material == 8) continue;
        for (const auto& tet : kuhn) march_tetrahedron(c, tet, position, emit);
      }
  return keep_measured_pieces(out);
}

}  // namespace scancell::planner
