#include "planner/core/rough_model.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <sstream>

#include <tbb/parallel_invoke.h>

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModEdgeLengthT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

#include "common/errors.hpp"

namespace scancell::planner {
namespace {

// Double-precision points: decimation by halfedge collapse then keeps surviving vertices bit-exact, which
// the DECOUPLED generator relies on to map RM_v vertices back to RM_s rows.
struct DoubleTraits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
};
using OMeshBase = OpenMesh::TriMesh_ArrayKernelT<DoubleTraits>;

/// The mesh the decimater works on: OpenMesh's own, with the collapse test compiled here. Debian's
/// libOpenMeshCore is built with assertions on, and its is_collapse_ok reads every status flag through a
/// property accessor that asserts on the property's type name (a std::string built and compared per access):
/// that was over half of a decimation's time (86k -> 5k vertices: 4.5 s, 57 % in is_collapse_ok, memcmp,
/// malloc and free). DecimaterT calls `mesh_.is_collapse_ok` on this type, so this one, the same test
/// (OpenMesh's TriConnectivity::is_collapse_ok: the link condition, no boundary ear, no interior edge
/// between two boundary vertices), runs instead; the same collapses are taken, so the rough model is the
/// same to the bit.
struct OMesh : OMeshBase {
  bool is_collapse_ok(HalfedgeHandle v0v1) {
    if (status(edge_handle(v0v1)).deleted()) return false;
    const HalfedgeHandle v1v0 = opposite_halfedge_handle(v0v1);
    const VertexHandle v0 = to_vertex_handle(v1v0), v1 = to_vertex_handle(v0v1);
    if (status(v0).deleted() || status(v1).deleted()) return false;
    // The third vertex of each face on the edge; an edge of a face whose other two edges are both on the
    // boundary cannot go (it would leave a dangling face).
    auto apex = [&](HalfedgeHandle h, VertexHandle& v) {
      if (is_boundary(h)) return true;
      const HalfedgeHandle h1 = next_halfedge_handle(h), h2 = next_halfedge_handle(h1);
      v = to_vertex_handle(h1);
      return !(is_boundary(opposite_halfedge_handle(h1)) && is_boundary(opposite_halfedge_handle(h2)));
    };
    VertexHandle vl, vr;
    if (!apex(v0v1, vl) || !apex(v1v0, vr) || vl == vr) return false;
    // Link condition: the one-rings of v0 and v1 share only vl and vr.
    for (auto it = vv_iter(v0); it.is_valid(); ++it) status(*it).set_tagged(false);
    for (auto it = vv_iter(v1); it.is_valid(); ++it) status(*it).set_tagged(true);
    for (auto it = vv_iter(v0); it.is_valid(); ++it)
      if (status(*it).tagged() && *it != vl && *it != vr) return false;
    return !(is_boundary(v0) && is_boundary(v1) && !is_boundary(v0v1) && !is_boundary(v1v0));
  }
};

std::uint64_t spread_bits(std::uint64_t x) {  // 21 bits -> every third bit of 63
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffull;
  x = (x | x << 16) & 0x1f0000ff0000ffull;
  x = (x | x << 8) & 0x100f00f00f00f00full;
  x = (x | x << 4) & 0x10c30c30c30c30c3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

void check_label_count(const std::vector<int>& labels, std::size_t vertices) {
  if (!labels.empty() && labels.size() != vertices)
    throw ConfigError("segments: " + std::to_string(labels.size()) + " labels for " + std::to_string(vertices) +
                      " mesh vertices");
}

}  // namespace

namespace {

/// Fills `om` with `mesh` (its k-th vertex the k-th), the `locked` vertices never to be removed (a neighbour
/// may collapse onto one; it stays). Counts the faces OpenMesh refuses (complex edge, non-manifold). Kept
/// apart from the collapses: OpenMesh reports a refused face on its one global log stream, which the two
/// halves' threads must not write at once.
void fill_omesh(OMesh& om, const TriangleMesh& mesh, const std::vector<std::uint8_t>& locked, std::size_t* faces_rejected) {
  std::vector<OMesh::VertexHandle> vh;
  vh.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) vh.push_back(om.add_vertex(OMesh::Point(v.x(), v.y(), v.z())));
  std::size_t rejected = 0;
  for (const auto& t : mesh.triangles) {
    if (!om.add_face(vh[t[0]], vh[t[1]], vh[t[2]]).is_valid()) ++rejected;  // complex edge / non-manifold
  }
  if (faces_rejected) *faces_rejected = rejected;
  om.request_vertex_status();
  for (std::size_t v = 0; v < locked.size(); ++v)
    if (locked[v]) om.status(vh[v]).set_locked(true);
}

/// Quadric decimation of `om` to `target_vertices`, no edge longer than 2·even_edge collapsed. Returns the
/// surviving mesh and, per surviving vertex, its index in the mesh `om` was filled with.
TriangleMesh collapse_to(OMesh& om, std::size_t target_vertices, double even_edge, std::vector<std::uint32_t>* source) {
  om.request_face_normals();  // ModNormalFlipping compares face normals before and after each collapse
  om.update_face_normals();
  OpenMesh::Decimater::DecimaterT<OMesh> decimater(om);
  OpenMesh::Decimater::ModQuadricT<OMesh>::Handle quadric;
  decimater.add(quadric);
  decimater.module(quadric).unset_max_err();
  // A rough model stands in for a rough scan, which samples the surface roughly evenly. Pure quadric
  // decimation turns flat regions into a few huge (and sometimes flipped) triangles: one viewpoint position and
  // one averaged normal for a region larger than the sensor footprint. So no collapse may flip a face or turn
  // one by more than 60°, and no edge longer than twice the even spacing for the target count may collapse.
  OpenMesh::Decimater::ModNormalFlippingT<OMesh>::Handle flipping;
  decimater.add(flipping);
  decimater.module(flipping).set_max_normal_deviation(60.0);
  OpenMesh::Decimater::ModEdgeLengthT<OMesh>::Handle edge_length;
  decimater.add(edge_length);
  decimater.module(edge_length).set_edge_length(2.0 * even_edge);
  if (!decimater.initialize()) throw MeshError("decimation: OpenMesh decimater failed to initialise");
  decimater.decimate_to(target_vertices);
  OpenMesh::VPropHandleT<std::uint32_t> from;
  if (source) {
    om.add_property(from);
    for (auto v : om.all_vertices()) om.property(from, v) = static_cast<std::uint32_t>(v.idx());
  }
  om.garbage_collection();

  TriangleMesh out;
  out.vertices.reserve(om.n_vertices());
  for (auto v : om.vertices()) {
    const auto& p = om.point(v);
    out.vertices.emplace_back(p[0], p[1], p[2]);
    if (source) source->push_back(om.property(from, v));
  }
  for (auto f : om.faces()) {
    Triangle t;
    int k = 0;
    for (auto v : om.fv_range(f)) t[k++] = static_cast<std::uint32_t>(v.idx());
    out.triangles.push_back(t);
  }
  return out;
}

double even_edge_for(const TriangleMesh& mesh, std::size_t target_vertices) {
  double area = 0.0;
  for (const auto& t : mesh.triangles) area += triangle_area(mesh, t);
  return std::sqrt(2.0 * area / (std::sqrt(3.0) * std::max<std::size_t>(target_vertices, 1)));
}

TriangleMesh decimate_in_one_pass(const TriangleMesh& mesh, std::size_t target_vertices, double even_edge, std::size_t* faces_rejected) {
  OMesh om;
  fill_omesh(om, mesh, {}, faces_rejected);
  return collapse_to(om, target_vertices, even_edge, nullptr);
}

/// A mesh cut in two by its faces: each part's triangles over its own vertices, which mesh vertex each is,
/// and which of them the other part uses too (the seam).
struct Halves {
  std::array<TriangleMesh, 2> part;
  std::array<std::vector<std::uint32_t>, 2> global;  // part vertex -> mesh vertex
  std::array<std::vector<std::uint8_t>, 2> seam;     // per part vertex
  std::vector<std::uint8_t> on_seam;                 // per mesh vertex
  std::size_t seam_vertices = 0, used_vertices = 0;
};

/// Faces by their centroid against the median centroid along the longest side of the bounding box: the
/// halves have about as many faces each, and the cut depends on the mesh alone.
Halves cut_in_halves(const TriangleMesh& mesh) {
  Eigen::Vector3d lo = mesh.vertices.front(), hi = lo;
  for (const auto& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  std::vector<double> c(mesh.triangles.size());
  for (std::size_t f = 0; f < c.size(); ++f) {
    const auto& t = mesh.triangles[f];
    c[f] = mesh.vertices[t[0]][axis] + mesh.vertices[t[1]][axis] + mesh.vertices[t[2]][axis];
  }
  std::vector<double> sorted = c;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double split = sorted[sorted.size() / 2];
  std::vector<std::uint8_t> sides(mesh.vertices.size(), 0);  // bit 0: used by part 0, bit 1: by part 1
  for (std::size_t f = 0; f < c.size(); ++f)
    for (auto v : mesh.triangles[f]) sides[v] |= c[f] < split ? 1 : 2;
  Halves h;
  h.on_seam.resize(mesh.vertices.size());
  for (std::size_t v = 0; v < sides.size(); ++v) {
    h.on_seam[v] = sides[v] == 3;
    h.seam_vertices += sides[v] == 3;
    h.used_vertices += sides[v] != 0;
  }
  for (int p = 0; p < 2; ++p) {
    std::vector<std::uint32_t> local(mesh.vertices.size(), UINT32_MAX);
    for (std::size_t f = 0; f < c.size(); ++f) {
      if ((c[f] < split) != (p == 0)) continue;
      Triangle t;
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t v = mesh.triangles[f][k];
        if (local[v] == UINT32_MAX) {
          local[v] = static_cast<std::uint32_t>(h.part[p].vertices.size());
          h.part[p].vertices.push_back(mesh.vertices[v]);
          h.global[p].push_back(v);
          h.seam[p].push_back(h.on_seam[v]);
        }
        t[k] = local[v];
      }
      h.part[p].triangles.push_back(t);
    }
  }
  return h;
}

/// The two decimated parts as one mesh, each seam vertex once; `band` marks the seam's vertices.
TriangleMesh join_halves(const Halves& h, const std::array<TriangleMesh, 2>& coarse,
                         const std::array<std::vector<std::uint32_t>, 2>& source, std::vector<std::uint8_t>& band) {
  TriangleMesh merged;
  std::vector<std::uint32_t> at(h.on_seam.size(), UINT32_MAX);
  for (int p = 0; p < 2; ++p) {
    std::vector<std::uint32_t> idx(coarse[p].vertices.size());
    for (std::size_t v = 0; v < idx.size(); ++v) {
      const std::uint32_t g = h.global[p][source[p][v]];
      if (at[g] == UINT32_MAX) {
        at[g] = static_cast<std::uint32_t>(merged.vertices.size());
        merged.vertices.push_back(coarse[p].vertices[v]);
        band.push_back(h.on_seam[g]);
      }
      idx[v] = at[g];
    }
    for (const auto& t : coarse[p].triangles) merged.triangles.push_back({idx[t[0]], idx[t[1]], idx[t[2]]});
  }
  return merged;
}

/// Decimation on two cores with a result that does not depend on how many there are: the halves at once,
/// each to its share of the target with its seam vertices kept, then the band along the seam (the seam's
/// vertices and their neighbours; the rest locked) down to the target. The collapse loop is sequential in
/// OpenMesh and was the larger part of a plan of a dense mesh (86k vertices: 1.9 of 3.8 s).
TriangleMesh decimate_halves(const TriangleMesh& mesh, std::size_t target_vertices, std::size_t* faces_rejected) {
  const double even_edge = even_edge_for(mesh, target_vertices);
  const Halves h = cut_in_halves(mesh);
  if (h.part[0].triangles.empty() || h.part[1].triangles.empty())  // every centroid on the median
    return decimate_in_one_pass(mesh, target_vertices, even_edge, faces_rejected);
  const double keep = static_cast<double>(target_vertices) / static_cast<double>(h.used_vertices);
  std::array<OMesh, 2> om;
  std::array<std::size_t, 2> rejected{0, 0};
  for (int p = 0; p < 2; ++p) fill_omesh(om[p], h.part[p], h.seam[p], &rejected[p]);
  std::array<TriangleMesh, 2> coarse;
  std::array<std::vector<std::uint32_t>, 2> source;
  auto run = [&](int p) {
    const std::size_t own = h.part[p].vertices.size() - h.seam_vertices;
    const std::size_t t = static_cast<std::size_t>(std::lround(keep * static_cast<double>(own))) + h.seam_vertices;
    coarse[p] = collapse_to(om[p], t, even_edge, &source[p]);
  };
  tbb::parallel_invoke([&] { run(0); }, [&] { run(1); });
  std::vector<std::uint8_t> band;
  const TriangleMesh merged = join_halves(h, coarse, source, band);
  std::vector<std::uint8_t> locked = band;
  for (const auto& t : merged.triangles)
    if (band[t[0]] || band[t[1]] || band[t[2]]) locked[t[0]] = locked[t[1]] = locked[t[2]] = 1;
  for (auto& v : locked) v = !v;
  std::size_t final_rejected = 0;
  OMesh joined;
  fill_omesh(joined, merged, locked, &final_rejected);
  if (faces_rejected) *faces_rejected = rejected[0] + rejected[1] + final_rejected;
  return collapse_to(joined, target_vertices, even_edge, nullptr);
}

}  // namespace

TriangleMesh decimate(const TriangleMesh& mesh, std::size_t target_vertices, std::size_t* faces_rejected) {
  const bool halves = mesh.vertices.size() >= kDecimateInHalvesMinVertices && mesh.vertices.size() >= 4 * target_vertices;
  TriangleMesh out = halves ? decimate_halves(mesh, target_vertices, faces_rejected)
                            : decimate_in_one_pass(mesh, target_vertices, even_edge_for(mesh, target_vertices), faces_rejected);
  validate_mesh(out, "decimated mesh");
  return out;
}

std::vector<Eigen::Vector3d> area_weighted_normals(const TriangleMesh& mesh) {
  std::vector<Eigen::Vector3d> n(mesh.vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d& a = mesh.vertices[t[0]];
    const Eigen::Vector3d fn = (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a);
    for (auto i : t) n[i] += fn;
  }
  for (auto& v : n) {
    const double len = v.norm();
    // A vertex whose face normals cancel (a knife edge) has no defined normal; keep zero so that no
    // viewpoint counts it as facing, rather than inventing a direction.
    v = len > 0.0 ? Eigen::Vector3d(v / len) : Eigen::Vector3d::Zero();
  }
  return n;
}

std::vector<std::uint32_t> crease_rows(const RoughModel& rough, double min_angle_rad) {
  const double cos_max = std::cos(min_angle_rad);
  std::vector<std::uint8_t> crease(rough.size(), 0);
  for (std::size_t r = 0; r < rough.size(); ++r) crease[r] = rough.normals[r].squaredNorm() == 0.0;
  for (const auto& t : rough.triangles) {
    const Eigen::Vector3d& a = rough.points[t[0]];
    const Eigen::Vector3d fn = (rough.points[t[1]] - a).cross(rough.points[t[2]] - a);
    const double len = fn.norm();
    if (len == 0.0) continue;  // a degenerate triangle has no direction to differ by
    for (auto v : t)
      if (fn.dot(rough.normals[v]) < cos_max * len) crease[v] = 1;
  }
  std::vector<std::uint32_t> out;
  for (std::uint32_t r = 0; r < crease.size(); ++r)
    if (crease[r]) out.push_back(r);
  return out;
}

RoughModel make_rough_model(const TriangleMesh& mesh, const std::vector<int>& labels, const std::vector<std::uint8_t>& hypothetical) {
  check_label_count(labels, mesh.vertices.size());
  const std::size_t n = mesh.vertices.size();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& v : mesh.vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const Eigen::Vector3d ext = (hi - lo).cwiseMax(1e-12);
  std::vector<std::uint64_t> code(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d q = ((mesh.vertices[i] - lo).cwiseQuotient(ext) * 2097151.0).cwiseMax(0.0);
    code[i] = spread_bits(static_cast<std::uint64_t>(q.x())) | spread_bits(static_cast<std::uint64_t>(q.y())) << 1 |
              spread_bits(static_cast<std::uint64_t>(q.z())) << 2;
  }
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return code[a] < code[b]; });
  std::vector<std::uint32_t> rank(n);
  for (std::size_t i = 0; i < n; ++i) rank[order[i]] = static_cast<std::uint32_t>(i);

  RoughModel rm;
  rm.points.resize(n);
  for (std::size_t i = 0; i < n; ++i) rm.points[i] = mesh.vertices[order[i]];
  if (!labels.empty()) {
    rm.segment.resize(n);
    for (std::size_t i = 0; i < n; ++i) rm.segment[i] = labels[order[i]];
  }
  if (!hypothetical.empty()) {
    if (hypothetical.size() != n)
      throw ConfigError("rough model: " + std::to_string(hypothetical.size()) + " hypothetical flags for " + std::to_string(n) + " vertices");
    rm.hypothetical.resize(n);
    for (std::size_t i = 0; i < n; ++i) rm.hypothetical[i] = hypothetical[order[i]];
  }
  rm.triangles = mesh.triangles;
  for (auto& t : rm.triangles)
    for (auto& i : t) i = rank[i];
  const TriangleMesh sorted{rm.points, rm.triangles};
  rm.normals = area_weighted_normals(sorted);
  rm.area_mm2.assign(n, 0.0);
  double edge_sum = 0.0;
  for (const auto& t : rm.triangles) {
    const double a = triangle_area(sorted, t);
    rm.total_area_mm2 += a;
    for (auto i : t) rm.area_mm2[i] += a / 3.0;
    for (int k = 0; k < 3; ++k) edge_sum += (rm.points[t[k]] - rm.points[t[(k + 1) % 3]]).norm();
  }
  rm.mean_edge_mm = rm.triangles.empty() ? 0.0 : edge_sum / (3.0 * rm.triangles.size());
  return rm;
}

namespace {

/// Per-vertex values of `fine` for the vertices of `coarse` found at the same position (`missing` if none).
template <class T>
std::vector<T> carry_by_position(const TriangleMesh& fine, const TriangleMesh& coarse, const std::vector<T>& values, T missing) {
  std::map<std::array<double, 3>, T> at;
  for (std::size_t i = 0; i < fine.vertices.size(); ++i) at[{fine.vertices[i].x(), fine.vertices[i].y(), fine.vertices[i].z()}] = values[i];
  std::vector<T> kept(coarse.vertices.size(), missing);
  for (std::size_t i = 0; i < coarse.vertices.size(); ++i) {
    const auto it = at.find({coarse.vertices[i].x(), coarse.vertices[i].y(), coarse.vertices[i].z()});
    if (it != at.end()) kept[i] = it->second;
  }
  return kept;
}

}  // namespace

RoughModel build_rough_model(TriangleMesh mesh, const RoughModelOptions& options, RoughModelReport* report) {
  RoughModelReport r;
  r.input_vertices = mesh.vertices.size();
  std::vector<int> labels = options.vertex_labels;
  std::vector<std::uint8_t> hypothetical = options.vertex_hypothetical;
  if (!hypothetical.empty() && hypothetical.size() != mesh.vertices.size())
    throw ConfigError("rough model: " + std::to_string(hypothetical.size()) + " hypothetical flags for " +
                      std::to_string(mesh.vertices.size()) + " vertices");
  if (options.target_vertices && options.rho_rel)
    throw ConfigError("rough model: give either a target vertex count or rho_rel, not both");
  check_label_count(labels, mesh.vertices.size());
  std::optional<std::size_t> target = options.target_vertices;
  if (options.rho_rel) {
    if (!(*options.rho_rel <= 0.0)) throw ConfigError("rough model: rho_rel must be <= 0 (a rough model is sparser)");
    target = static_cast<std::size_t>(std::llround(mesh.vertices.size() * std::exp2(*options.rho_rel)));
  }
  if (target) {
    if (*target < 4) throw ConfigError("rough model: target vertex count must be at least 4");
    if (*target < mesh.vertices.size()) {
      TriangleMesh coarse = decimate(mesh, *target, &r.faces_rejected_by_decimator);
      // Surviving vertices are bit-exact copies of input vertices: carry their labels and flags across.
      if (!labels.empty()) labels = carry_by_position(mesh, coarse, labels, -1);
      if (!hypothetical.empty()) hypothetical = carry_by_position(mesh, coarse, hypothetical, std::uint8_t{0});
      mesh = std::move(coarse);
      r.decimated = true;
    }
  }
  if (options.normal_noise_mm < 0.0 || !std::isfinite(options.normal_noise_mm))
    throw ConfigError("rough model: normal noise must be finite and >= 0 mm");
  if (options.surface_error_mm < 0.0 || !std::isfinite(options.surface_error_mm))
    throw ConfigError("rough model: surface error must be finite and >= 0 mm, got " + std::to_string(options.surface_error_mm));
  if (options.normal_noise_mm > 0.0) {
    // Thesis 5.4: rough-model sampling error as Gaussian displacement along the local normal.
    const auto n = area_weighted_normals(mesh);
    std::mt19937_64 rng(options.seed);
    std::normal_distribution<double> gauss(0.0, options.normal_noise_mm);
    for (std::size_t i = 0; i < mesh.vertices.size(); ++i) mesh.vertices[i] += gauss(rng) * n[i];
  }
  r.output_vertices = mesh.vertices.size();
  if (report) *report = r;
  return make_rough_model(mesh, labels, hypothetical);
}

}  // namespace scancell::planner
