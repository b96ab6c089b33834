#include "planner/reconstruction/surface_mesh.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>

#include "common/binary.hpp"
#include "common/errors.hpp"

namespace scancell::planner {

SurfaceMesh mesh_from_oriented_points(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
                                      const SurfaceMeshOptions& o) {
  if (points.size() != normals.size()) throw DataError("surface mesh: " + std::to_string(points.size()) + " points, " + std::to_string(normals.size()) + " normals");
  if (!(o.voxel_mm > 0.0) || !(o.radius_voxels >= 1.0)) throw DataError("surface mesh: voxel_mm must be > 0 and radius_voxels >= 1");
  static std::once_flag init;
  std::call_once(init, [] { openvdb::initialize(); });
  const double h = o.voxel_mm;
  // Sums of w·n·(x − p) and of w per voxel, sparse: only voxels within the radius of a sample exist.
  openvdb::FloatGrid::Ptr sum = openvdb::FloatGrid::create(0.0f), weight = openvdb::FloatGrid::create(0.0f);
  auto sa = sum->getAccessor();
  auto wa = weight->getAccessor();
  const int reach = static_cast<int>(std::ceil(o.radius_voxels));
  const double r2 = o.radius_voxels * o.radius_voxels;
  for (std::size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3d& n = normals[k];
    if (!(n.squaredNorm() > 0.25) || !points[k].allFinite()) continue;
    const Eigen::Vector3d g = points[k] / h;  // in voxel units
    const openvdb::Coord c(static_cast<int>(std::lround(g.x())), static_cast<int>(std::lround(g.y())), static_cast<int>(std::lround(g.z())));
    for (int dx = -reach; dx <= reach; ++dx)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dz = -reach; dz <= reach; ++dz) {
          const openvdb::Coord v = c.offsetBy(dx, dy, dz);
          const Eigen::Vector3d d = Eigen::Vector3d(v.x(), v.y(), v.z()) - g;
          const double q = d.squaredNorm();
          if (q > r2) continue;
          const double w = std::exp(-0.5 * q);  // σ = one voxel
          sa.setValue(v, sa.getValue(v) + static_cast<float>(w * n.dot(d) * h));
          wa.setValue(v, wa.getValue(v) + static_cast<float>(w));
        }
  }
  // The field (mm) where enough weight is, then the mask of cells that may carry surface: a cell (min corner
  // v) whose 8 corners all have a value and change sign. A cell with a corner in the background would put a
  // false second surface behind the band's far side, or close an unmeasured hole.
  const float background = static_cast<float>(3.0 * h);
  openvdb::FloatGrid::Ptr sdf = openvdb::FloatGrid::create(background);
  sdf->setTransform(openvdb::math::Transform::createLinearTransform(h));
  sdf->setGridClass(openvdb::GRID_LEVEL_SET);
  openvdb::BoolGrid::Ptr mask = openvdb::BoolGrid::create(false);
  mask->setTransform(sdf->transform().copy());
  auto fa = sdf->getAccessor();
  auto ma = mask->getAccessor();
  for (auto it = weight->cbeginValueOn(); it; ++it) {
    const float w = *it;
    if (w < o.min_weight) continue;
    const float d = sa.getValue(it.getCoord()) / w;
    fa.setValue(it.getCoord(), d);
  }
  for (auto it = sdf->cbeginValueOn(); it; ++it) {
    bool neg = false, pos = false, whole = true;
    for (int k = 0; k < 8 && whole; ++k) {
      const openvdb::Coord q = it.getCoord().offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      whole = fa.isValueOn(q);
      const float d = fa.getValue(q);
      neg = neg || d < 0.0f;
      pos = pos || d >= 0.0f;
    }
    if (whole && neg && pos) ma.setValue(it.getCoord(), true);
  }
  SurfaceMesh out;
  out.active_voxels = sdf->activeVoxelCount();
  openvdb::tools::VolumeToMesh mesher(0.0, 0.0);
  mesher.setSurfaceMask(mask, false);
  mesher(*sdf);
  out.mesh.vertices.reserve(mesher.pointListSize());
  for (std::size_t i = 0; i < mesher.pointListSize(); ++i) {
    const openvdb::Vec3s& p = mesher.pointList()[i];
    out.mesh.vertices.emplace_back(p.x(), p.y(), p.z());
  }
  for (std::size_t pi = 0; pi < mesher.polygonPoolListSize(); ++pi) {
    const openvdb::tools::PolygonPool& pool = mesher.polygonPoolList()[pi];
    // VolumeToMesh winds its polygons the other way round from ours for a field negative inside.
    for (std::size_t q = 0; q < pool.numQuads(); ++q) {
      const openvdb::Vec4I& f = pool.quad(q);
      out.mesh.triangles.push_back({f[0], f[2], f[1]});
      out.mesh.triangles.push_back({f[0], f[3], f[2]});
    }
    for (std::size_t t = 0; t < pool.numTriangles(); ++t) {
      const openvdb::Vec3I& f = pool.triangle(t);
      out.mesh.triangles.push_back({f[0], f[2], f[1]});
    }
  }
  // Support at each vertex: the summed weight of the nearest voxel.
  out.support.reserve(out.mesh.vertices.size());
  for (const auto& v : out.mesh.vertices) {
    // The most supported corner of the cell the vertex lies in.
    const openvdb::Coord c(static_cast<int>(std::floor(v.x() / h)), static_cast<int>(std::floor(v.y() / h)), static_cast<int>(std::floor(v.z() / h)));
    float w = 0.0f;
    for (int k = 0; k < 8; ++k) w = std::max(w, wa.getValue(c.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1)));
    out.support.push_back(w);
  }
  return out;
}

std::string surface_ply(const SurfaceMesh& s) {
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\ncomment scancell surface model 1 (mm; support: summed sample weight)\n"
    << "element vertex " << s.mesh.vertices.size() << "\nproperty float x\nproperty float y\nproperty float z\nproperty float support\n"
    << "element face " << s.mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  std::string buf = h.str();
  for (std::size_t i = 0; i < s.mesh.vertices.size(); ++i) {
    for (int c = 0; c < 3; ++c) scancell::append_binary<float>(buf, static_cast<float>(s.mesh.vertices[i][c]));
    scancell::append_binary<float>(buf, i < s.support.size() ? s.support[i] : 0.0f);
  }
  for (const auto& t : s.mesh.triangles) {
    scancell::append_binary<std::uint8_t>(buf, 3);
    for (int c = 0; c < 3; ++c) scancell::append_binary<std::int32_t>(buf, static_cast<std::int32_t>(t[c]));
  }
  return buf;
}

}  // namespace scancell::planner
