#include "planner/fusion.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "planner/errors.hpp"

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
  // A corner that is material only by the conservative guess makes its cell's vertex hypothetical.
  auto guessed = [&](long i, long j, long k) {
    if (i <= 0 || j <= 0 || k <= 0 || i >= nx_ - 1 || j >= ny_ - 1 || k >= nz_ - 1 || below_floor(k)) return false;
    const std::size_t v = at(i, j, k);
    return weight_[v] == 0.0f && !carved_[v] && behind_[v] >= occluding_views_;
  };
  // One vertex per cell (min corner i, j, k) the surface crosses.
  std::unordered_map<std::size_t, std::uint32_t> vertex_of;
  const std::array<std::array<int, 3>, 8> corner = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 1}}};
  const std::array<std::array<int, 2>, 12> edges = {{{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3}, {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}}};
  auto cell_vertex = [&](long i, long j, long k) -> std::uint32_t {
    const std::size_t key = at(i, j, k);
    const auto it = vertex_of.find(key);
    if (it != vertex_of.end()) return it->second;
    std::array<float, 8> f;
    std::array<bool, 8> g;
    bool guess = false;
    for (int n = 0; n < 8; ++n) {
      const auto& cn = corner[static_cast<std::size_t>(n)];
      f[static_cast<std::size_t>(n)] = value(i + cn[0], j + cn[1], k + cn[2]);
      g[static_cast<std::size_t>(n)] = guessed(i + cn[0], j + cn[1], k + cn[2]);
    }
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int crossings = 0;
    for (const auto& e : edges) {
      const float a = f[static_cast<std::size_t>(e[0])], b = f[static_cast<std::size_t>(e[1])];
      if ((a < 0.0f) == (b < 0.0f)) continue;
      // A crossing against guessed material is a guess too.
      guess = guess || g[static_cast<std::size_t>(e[0])] || g[static_cast<std::size_t>(e[1])];
      const double t = a / (a - b);
      const auto& ca = corner[static_cast<std::size_t>(e[0])];
      const auto& cb = corner[static_cast<std::size_t>(e[1])];
      sum += Eigen::Vector3d(ca[0] + t * (cb[0] - ca[0]), ca[1] + t * (cb[1] - ca[1]), ca[2] + t * (cb[2] - ca[2]));
      ++crossings;
    }
    const Eigen::Vector3d local = crossings ? Eigen::Vector3d(sum / crossings) : Eigen::Vector3d(0.5, 0.5, 0.5);
    const auto id = static_cast<std::uint32_t>(out.mesh.vertices.size());
    out.mesh.vertices.push_back(centre(i, j, k) + voxel_ * local);
    out.hypothetical.push_back(guess);
    vertex_of.emplace(key, id);
    return id;
  };
  // One quad per grid edge whose ends differ in sign, joining the four cells around the edge; wound so that
  // the normal points from material (negative) to free space (positive).
  for (long k = 0; k + 1 < nz_; ++k)
    for (long j = 0; j + 1 < ny_; ++j)
      for (long i = 0; i + 1 < nx_; ++i) {
        const float f0 = value(i, j, k);
        for (int axis = 0; axis < 3; ++axis) {
          const long di = axis == 0, dj = axis == 1, dk = axis == 2;
          if (!inside(i + di, j + dj, k + dk)) continue;
          const float f1 = value(i + di, j + dj, k + dk);
          if ((f0 < 0.0f) == (f1 < 0.0f)) continue;
          // The four cells around edge (i,j,k)-(i+di,j+dj,k+dk): offsets in the two other axes.
          const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
          std::array<long, 3> base = {i, j, k};
          std::array<std::uint32_t, 4> q{};
          bool ok = true;
          const std::array<std::array<int, 2>, 4> around = {{{0, 0}, {-1, 0}, {-1, -1}, {0, -1}}};
          for (int n = 0; n < 4 && ok; ++n) {
            std::array<long, 3> c = base;
            c[static_cast<std::size_t>(a1)] += around[static_cast<std::size_t>(n)][0];
            c[static_cast<std::size_t>(a2)] += around[static_cast<std::size_t>(n)][1];
            if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] + 1 >= nx_ || c[1] + 1 >= ny_ || c[2] + 1 >= nz_) ok = false;
            else q[static_cast<std::size_t>(n)] = cell_vertex(c[0], c[1], c[2]);
          }
          if (!ok) continue;
          // (a1, a2, axis) is right-handed: going round a1 → a2 gives a normal along +axis.
          if (f0 < 0.0f) {  // material at the low end: outward is +axis
            out.mesh.triangles.push_back({q[0], q[1], q[2]});
            out.mesh.triangles.push_back({q[0], q[2], q[3]});
          } else {
            out.mesh.triangles.push_back({q[0], q[3], q[2]});
            out.mesh.triangles.push_back({q[0], q[2], q[1]});
          }
        }
      }
  // A closed piece of surface without a single measured point on it (a shadow several views agree on, far
  // from the object; a bubble inside it) is not the object: keep only the pieces something was measured on.
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

}  // namespace scancell::planner
