#pragma once
#include <atomic>
// Indexed triangle meshes: loading (assimp) with strict validation, scaling, welding.
#include <array>
#include <cstdint>
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace scancell::planner {

using Triangle = std::array<std::uint32_t, 3>;

struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;  // mm once scaled
  std::vector<Triangle> triangles;
};

struct MeshLoadReport {
  std::size_t file_vertices = 0;        // as read, before welding
  std::size_t file_faces = 0;
  std::size_t degenerate_dropped = 0;   // zero-area or repeated-index triangles
  std::size_t unreferenced_vertices = 0;
};

/// Reads OFF, PLY, OBJ or STL through assimp. Throws MeshError naming the file and the offending element for
/// empty or unparseable files, non-finite coordinates, out-of-range indices and meshes without usable
/// triangles. Degenerate triangles are dropped and counted in the report. The file is parsed in a child
/// process that is stopped after `time_limit` (a malformed file can make a parser loop or crash; the caller
/// gets a MeshError naming the file either way).
/// A non-zero `cancel` stops the reader at once (MeshError "reading stopped"): a daemon that is stopping does
/// not wait out a slow or hanging file.
TriangleMesh load_mesh(const std::filesystem::path& path, MeshLoadReport* report = nullptr,
                       std::chrono::milliseconds time_limit = std::chrono::milliseconds(30000),
                       const std::atomic<int>* cancel = nullptr);

/// Validates an in-memory mesh with the same rules (name is used in messages); drops degenerate triangles.
void validate_mesh(TriangleMesh& mesh, const std::string& name, MeshLoadReport* report = nullptr);

/// Axis-aligned bounding box extent (max - min).
Eigen::Vector3d bounding_extent(const TriangleMesh& mesh);

/// Scale factor that makes the longest bounding-box side equal to longest_side_mm.
double fit_scale(const TriangleMesh& mesh, double longest_side_mm);

void apply_scale(TriangleMesh& mesh, double scale);

double triangle_area(const TriangleMesh& mesh, const Triangle& t);

/// How the triangles share their edges: `open` edges have one triangle (the rims of holes), `non_manifold` ones
/// three or more. A closed, manifold mesh has neither.
struct EdgeCounts {
  std::size_t edges = 0, open = 0, non_manifold = 0;
  bool closed() const { return open == 0 && non_manifold == 0; }
};
EdgeCounts count_edges(const TriangleMesh& mesh);
/// 1 for each vertex on an open edge (one triangle uses it: the rim of an open mesh or of a hole), else 0.
std::vector<std::uint8_t> open_edge_vertices(const TriangleMesh& mesh);

/// Appends `more` to `into` (its triangles after into's, so ids below the old count stay into's).
void append_mesh(TriangleMesh& into, const TriangleMesh& more);

/// Splits every edge longer than max_edge_mm at its midpoint (passes of conforming 1-to-2/3/4 triangle splits,
/// winding kept) until none is: the surface is unchanged, only sampled more densely. Makes a coarse CAD or
/// sample mesh a fine model whose vertices sample the surface evenly, so vertex-weighted m_v and ρ_rel mean the
/// same on every object.
TriangleMesh refine_edges(const TriangleMesh& mesh, double max_edge_mm);

}  // namespace scancell::planner
