#include "planner/kinematics/resting_poses.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

#include "common/errors.hpp"

namespace scancell::planner {

namespace {

struct HullFace {
  Eigen::Vector3d normal;           // outward, unit
  double offset = 0.0;              // normal·x + offset = 0 on the face
  std::vector<int> polygon;         // hull point ids, counter-clockwise seen from outside
};

std::string extent_text(const TriangleMesh& mesh) {
  const Eigen::Vector3d e = bounding_extent(mesh);
  std::ostringstream s;
  s << e.x() << " x " << e.y() << " x " << e.z() << " mm";
  return s.str();
}

/// Centre of the enclosed volume when every edge has two triangles (and the volume is not nil), else of
/// the surface area.
Eigen::Vector3d centre_of_mass(const TriangleMesh& mesh, bool* solid) {
  const bool closed = count_edges(mesh).closed();
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(v);
  const Eigen::Vector3d o = box.center();  // origin of the tetrahedra: keeps the sums well conditioned
  double volume = 0.0, area = 0.0;
  Eigen::Vector3d vol_moment = Eigen::Vector3d::Zero(), area_moment = Eigen::Vector3d::Zero();
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]] - o, b = mesh.vertices[t[1]] - o, c = mesh.vertices[t[2]] - o;
    const double v = a.dot(b.cross(c)) / 6.0;
    volume += v;
    vol_moment += v * (a + b + c) / 4.0;
    const double s = 0.5 * (b - a).cross(c - a).norm();
    area += s;
    area_moment += s * (a + b + c) / 3.0;
  }
  *solid = closed && std::abs(volume) > 1e-9 * box.volume();
  if (*solid) return o + vol_moment / volume;
  return o + area_moment / area;
}

/// The convex hull's faces, coplanar facets merged within `merge_mm`. Point ids are mesh vertex ids.
std::vector<HullFace> hull_faces(const TriangleMesh& mesh, double merge_mm) {
  std::vector<coordT> pts;
  pts.reserve(mesh.vertices.size() * 3);
  for (const auto& v : mesh.vertices) pts.insert(pts.end(), {v.x(), v.y(), v.z()});
  char* err_text = nullptr;
  std::size_t err_size = 0;
  FILE* err = open_memstream(&err_text, &err_size);
  qhT qh_storage;
  qhT* qh = &qh_storage;
  qh_zero(qh, err);
  std::string cmd = "qhull C-" + std::to_string(merge_mm);
  std::vector<HullFace> faces;
  const int code = qh_new_qhull(qh, 3, static_cast<int>(mesh.vertices.size()), pts.data(), False, cmd.data(), nullptr, err);
  if (code == 0) {
    facetT* facet;
    FORALLfacets {
      HullFace f;
      f.normal = Eigen::Vector3d(facet->normal[0], facet->normal[1], facet->normal[2]).normalized();
      f.offset = facet->offset;
      // Order the face's vertices counter-clockwise about its outward normal (a convex polygon).
      const Eigen::Vector3d u = f.normal.unitOrthogonal(), w = f.normal.cross(u);
      std::vector<std::pair<double, int>> ring;
      Eigen::Vector3d mid = Eigen::Vector3d::Zero();
      std::vector<int> ids;
      vertexT *vertex, **vertexp;
      FOREACHvertex_(facet->vertices) ids.push_back(qh_pointid(qh, vertex->point));
      for (int id : ids) mid += mesh.vertices[id];
      mid /= static_cast<double>(ids.size());
      for (int id : ids) {
        const Eigen::Vector3d d = mesh.vertices[id] - mid;
        ring.emplace_back(std::atan2(d.dot(w), d.dot(u)), id);
      }
      std::sort(ring.begin(), ring.end());
      for (const auto& [angle, id] : ring) f.polygon.push_back(id);
      faces.push_back(std::move(f));
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  std::fclose(err);
  const std::string message = err_text ? std::string(err_text, err_size) : std::string();
  std::free(err_text);
  if (code != 0) {
    const std::string first = message.substr(0, message.find('\n', message.find_first_not_of('\n')));
    throw DataError("resting poses: no convex hull of a mesh of " + std::to_string(mesh.vertices.size()) +
                    " vertices, extent " + extent_text(mesh) + " (qhull: " + first + ")");
  }
  return faces;
}

/// Solid angle of a convex polygon seen from `c` (Van Oosterom & Strackee, one fan triangle at a time).
double solid_angle(const std::vector<Eigen::Vector3d>& poly, const Eigen::Vector3d& c) {
  double omega = 0.0;
  const Eigen::Vector3d r1 = poly[0] - c;
  for (std::size_t i = 1; i + 1 < poly.size(); ++i) {
    const Eigen::Vector3d r2 = poly[i] - c, r3 = poly[i + 1] - c;
    const double l1 = r1.norm(), l2 = r2.norm(), l3 = r3.norm();
    const double num = std::abs(r1.dot(r2.cross(r3)));
    const double den = l1 * l2 * l3 + r1.dot(r2) * l3 + r1.dot(r3) * l2 + r2.dot(r3) * l1;
    omega += 2.0 * std::atan2(num, den);
  }
  return omega;
}

}  // namespace

RestingPoses resting_poses(const TriangleMesh& mesh, const RestingPoseOptions& options) {
  if (mesh.vertices.size() < 4 || mesh.triangles.empty())
    throw DataError("resting poses: a mesh of " + std::to_string(mesh.vertices.size()) + " vertices has no volume to rest");
  RestingPoses out;
  out.centre_of_mass = centre_of_mass(mesh, &out.solid);
  const double merge = options.merge_mm > 0.0 ? options.merge_mm : 0.002 * bounding_extent(mesh).norm();
  const std::vector<HullFace> faces = hull_faces(mesh, merge);
  out.hull_faces = faces.size();
  const Eigen::Vector3d& c = out.centre_of_mass;

  // Per face: the centre of mass's foot against the support polygon. Inside: stable, with its margin.
  // Outside: the body tips over the edge it overhangs most, onto the face across that edge.
  std::map<std::pair<int, int>, std::vector<int>> faces_of_edge;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    const auto& p = faces[f].polygon;
    for (std::size_t i = 0; i < p.size(); ++i) faces_of_edge[std::minmax(p[i], p[(i + 1) % p.size()])].push_back(f);
  }
  std::vector<double> omega(faces.size()), margin(faces.size());
  std::vector<int> rolls_to(faces.size(), -1);
  double omega_total = 0.0;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    const HullFace& h = faces[f];
    std::vector<Eigen::Vector3d> poly;
    for (int id : h.polygon) poly.push_back(mesh.vertices[id]);
    omega[f] = solid_angle(poly, c);
    omega_total += omega[f];
    const Eigen::Vector3d foot = c - (h.normal.dot(c) + h.offset) * h.normal;
    double worst = -1e300;
    int worst_edge = -1;
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector3d e = poly[(i + 1) % poly.size()] - poly[i];
      const Eigen::Vector3d out_dir = e.cross(h.normal).normalized();  // in the face's plane, away from it
      const double d = (foot - poly[i]).dot(out_dir);
      if (d > worst) worst = d, worst_edge = static_cast<int>(i);
    }
    margin[f] = -worst;
    if (worst > 0.0) {
      const auto& across = faces_of_edge[std::minmax(h.polygon[worst_edge], h.polygon[(worst_edge + 1) % poly.size()])];
      for (int g : across)
        if (g != f) rolls_to[f] = g;
    }
  }
  // Follow each unstable face's roll to where it settles (a cycle, which roundoff could make, keeps its share
  // out of every pose rather than inventing one).
  std::vector<double> share(faces.size(), 0.0);
  std::vector<int> settles(faces.size(), -1);
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    int at = f;
    for (std::size_t step = 0; at >= 0 && margin[at] < 0.0 && step <= faces.size(); ++step) at = rolls_to[at];
    if (at >= 0 && margin[at] >= 0.0) {
      share[at] += omega[f];
      settles[f] = at;
    }
  }
  std::vector<int> face_of_pose;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    if (margin[f] < 0.0 || share[f] <= 0.0) continue;
    face_of_pose.push_back(f);
    const HullFace& h = faces[f];
    RestingPose r;
    r.down_object = h.normal;
    r.object_to_table = Eigen::Quaterniond::FromTwoVectors(h.normal, -Eigen::Vector3d::UnitZ()).toRotationMatrix();
    r.probability = share[f] / omega_total;
    r.margin_mm = margin[f];
    r.com_height_mm = -(h.normal.dot(c) + h.offset);
    r.tip_angle_rad = std::atan2(r.margin_mm, r.com_height_mm);
    for (std::size_t i = 1; i + 1 < h.polygon.size(); ++i)
      r.support_area_mm2 += 0.5 * (mesh.vertices[h.polygon[i]] - mesh.vertices[h.polygon[0]])
                                      .cross(mesh.vertices[h.polygon[i + 1]] - mesh.vertices[h.polygon[0]])
                                      .norm();
    out.poses.push_back(r);
  }
  std::vector<int> order(out.poses.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return out.poses[a].probability > out.poses[b].probability; });
  std::vector<RestingPose> sorted;
  std::vector<int> pose_of_face(faces.size(), -1);
  for (int k : order) {
    pose_of_face[face_of_pose[k]] = static_cast<int>(sorted.size());
    sorted.push_back(out.poses[k]);
  }
  out.poses = std::move(sorted);
  for (int f = 0; f < static_cast<int>(faces.size()); ++f)
    out.basins.push_back({faces[f].normal, faces[f].offset, settles[f] < 0 ? -1 : pose_of_face[settles[f]]});
  return out;
}

int settling_pose(const RestingPoses& rest, const Eigen::Vector3d& down_object) {
  // The hull face the ray from the centre of mass along `down` leaves through (the first plane it crosses).
  const Eigen::Vector3d d = down_object.normalized();
  double best = 1e300;
  int pose = -1;
  for (const auto& b : rest.basins) {
    const double along = b.normal.dot(d);
    if (along <= 0.0) continue;
    const double t = -(b.normal.dot(rest.centre_of_mass) + b.offset) / along;
    if (t < best) best = t, pose = b.pose;
  }
  return pose;
}

Eigen::Isometry3d place_on_plate(const TriangleMesh& mesh, const Eigen::Matrix3d& rotation, const Eigen::Vector3d& offset_mm) {
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(rotation * v);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = rotation;
  t.translation() = offset_mm + Eigen::Vector3d(-box.center().x(), -box.center().y(), -box.min().z());
  return t;
}

Eigen::Vector3d plate_offset_of(const TriangleMesh& mesh, const Eigen::Isometry3d& pose) {
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(pose.linear() * v);
  return pose.translation() + Eigen::Vector3d(box.center().x(), box.center().y(), box.min().z());
}

}  // namespace scancell::planner
