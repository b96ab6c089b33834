#pragma once
// Objects no one tuned the planner on (issue 15: "the project will also be checked on objects it has not
// seen"): five shapes made here, never among the shared meshes or the CAD parts the quality figures were read
// on, each a closed mesh scaled to a 200 mm longest side as the shared meshes are.
// - stairs: six steps (right-angle ledges and inside corners, a shape made of faces and nothing else);
// - bracket: an L with a square window through its upright (a through hole seen edge on by most views);
// - gear: 18 trapezoid teeth round a bore (narrow clefts whose flanks face each other);
// - goblet: a solid of revolution, a wide bowl over a thin stem (overhang, a neck the plate's views look up at);
// - torus: lying on the plate (its underside faces the plate all round, its hole faces inwards).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <numbers>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench_objects.hpp"
#include "planner/geometry/mesh.hpp"

namespace scancell::bench {
namespace generated {

using Mesh = planner::TriangleMesh;

/// The boundary of a set of cubic cells (cell_mm on a side; `filled(i, j, k)` over an n[0]×n[1]×n[2] grid),
/// each exposed face two triangles wound outwards, vertices shared: closed wherever no two cells meet at an
/// edge or a corner alone.
inline Mesh cell_solid(const std::function<bool(int, int, int)>& filled, std::array<int, 3> n, double cell_mm) {
  Mesh m;
  std::map<std::array<int, 3>, std::uint32_t> id;
  auto vertex = [&](std::array<int, 3> g) {
    const auto [it, added] = id.emplace(g, static_cast<std::uint32_t>(m.vertices.size()));
    if (added) m.vertices.emplace_back(g[0] * cell_mm, g[1] * cell_mm, g[2] * cell_mm);
    return it->second;
  };
  auto in = [&](int i, int j, int k) { return i >= 0 && j >= 0 && k >= 0 && i < n[0] && j < n[1] && k < n[2] && filled(i, j, k); };
  for (int i = 0; i < n[0]; ++i)
    for (int j = 0; j < n[1]; ++j)
      for (int k = 0; k < n[2]; ++k) {
        if (!in(i, j, k)) continue;
        for (int axis = 0; axis < 3; ++axis)
          for (int side = 0; side < 2; ++side) {
            std::array<int, 3> c{i, j, k};
            c[axis] += side ? 1 : -1;
            if (in(c[0], c[1], c[2])) continue;
            // The face's four corners, counter-clockwise seen from outside: the plane at `axis` = its side,
            // walked along the next axis then the one after (reversed on the low side).
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            std::array<int, 3> base{i, j, k};
            base[axis] += side;
            auto corner = [&](int du, int dv) {
              std::array<int, 3> g = base;
              g[u] += du, g[v] += dv;
              return vertex(g);
            };
            const std::uint32_t a = corner(0, 0), b = corner(1, 0), c2 = corner(1, 1), d = corner(0, 1);
            if (side) m.triangles.push_back({a, b, c2}), m.triangles.push_back({a, c2, d});
            else m.triangles.push_back({a, c2, b}), m.triangles.push_back({a, d, c2});
          }
      }
  return m;
}

/// Rings of `count` points joined into quads (two triangles each), ring a to ring b: wound so that the
/// triangle (a_i, a_i+1, b_i+1) faces outwards unless `flip`.
inline void join_rings(Mesh& m, std::uint32_t a, std::uint32_t b, std::uint32_t count, bool flip) {
  for (std::uint32_t i = 0; i < count; ++i) {
    const std::uint32_t j = (i + 1) % count;
    if (flip) m.triangles.push_back({a + i, b + j, a + j}), m.triangles.push_back({a + i, b + i, b + j});
    else m.triangles.push_back({a + i, a + j, b + j}), m.triangles.push_back({a + i, b + j, b + i});
  }
}

/// A ring of `count` points at height z, radius r(k) at angle 2πk/count; its first vertex's index.
inline std::uint32_t ring(Mesh& m, std::uint32_t count, double z, const std::function<double(std::uint32_t)>& r) {
  const auto first = static_cast<std::uint32_t>(m.vertices.size());
  for (std::uint32_t k = 0; k < count; ++k) {
    const double t = 2.0 * std::numbers::pi * k / count;
    m.vertices.emplace_back(r(k) * std::cos(t), r(k) * std::sin(t), z);
  }
  return first;
}

/// Six steps of 30 mm run and 20 mm rise, 100 mm wide (5 mm cells).
inline Mesh stairs() {
  return cell_solid([](int i, int, int k) { return k * 5.0 < 20.0 * (6 - (i * 5) / 30); }, {36, 20, 24}, 5.0);
}

/// An L, foot 150 × 25 mm and upright 25 × 120 mm, 90 mm deep, a 40 × 40 mm window through the upright.
inline Mesh bracket() {
  return cell_solid(
      [](int i, int j, int k) {
        const double x = (i + 0.5) * 5.0, y = (j + 0.5) * 5.0, z = (k + 0.5) * 5.0;
        const bool window = x < 25.0 && y > 25.0 && y < 65.0 && z > 55.0 && z < 95.0;
        return (z < 25.0 || x < 25.0) && !window;
      },
      {30, 18, 24}, 5.0);
}

/// 18 trapezoid teeth (root radius 80 mm, tip 95 mm) round a Ø50 mm bore, 40 mm thick.
inline Mesh gear() {
  constexpr std::uint32_t kTeeth = 18, kPerTooth = 16, n = kTeeth * kPerTooth;
  auto profile = [](std::uint32_t k) {
    const double ph = static_cast<double>(k % kPerTooth) / kPerTooth;
    if (ph < 0.2 || ph >= 0.8) return 80.0;
    if (ph < 0.35) return 80.0 + 15.0 * (ph - 0.2) / 0.15;
    if (ph < 0.65) return 95.0;
    return 95.0 - 15.0 * (ph - 0.65) / 0.15;
  };
  Mesh m;
  constexpr double kHeight = 40.0;
  // Faces: rings 5 mm apart from the bore (25 mm) out to the teeth, walls in eight layers.
  std::vector<std::uint32_t> bottom, top, outer, bore;
  for (int s = 0; s <= 11; ++s) {
    auto r = [&](std::uint32_t k) { return s == 11 ? profile(k) : 25.0 + 5.0 * s; };
    bottom.push_back(ring(m, n, 0.0, r));
    top.push_back(ring(m, n, kHeight, r));
  }
  outer.push_back(bottom.back()), bore.push_back(bottom.front());
  for (int l = 1; l < 8; ++l) {
    outer.push_back(ring(m, n, kHeight * l / 8.0, profile));
    bore.push_back(ring(m, n, kHeight * l / 8.0, [](std::uint32_t) { return 25.0; }));
  }
  outer.push_back(top.back()), bore.push_back(top.front());
  for (std::size_t s = 0; s + 1 < bottom.size(); ++s) join_rings(m, bottom[s + 1], bottom[s], n, true);
  for (std::size_t s = 0; s + 1 < top.size(); ++s) join_rings(m, top[s], top[s + 1], n, true);
  for (std::size_t l = 0; l + 1 < outer.size(); ++l) join_rings(m, outer[l], outer[l + 1], n, false);
  for (std::size_t l = 0; l + 1 < bore.size(); ++l) join_rings(m, bore[l], bore[l + 1], n, true);
  return m;
}

/// A solid of revolution 150 mm high: a foot (Ø90), a thin stem (Ø18) and a bowl widening to Ø120, closed.
inline Mesh goblet() {
  const std::vector<std::array<double, 2>> corners = {{45, 0},  {45, 6},   {12, 14},  {9, 40},  {9, 70},
                                                       {20, 78}, {45, 95}, {58, 120}, {60, 150}};
  std::vector<std::array<double, 2>> profile;  // (r, z), about 4 mm apart
  for (std::size_t c = 0; c + 1 < corners.size(); ++c) {
    const auto [r0, z0] = corners[c];
    const auto [r1, z1] = corners[c + 1];
    const int steps = std::max(1, static_cast<int>(std::hypot(r1 - r0, z1 - z0) / 4.0));
    for (int s = 0; s < steps; ++s) profile.push_back({r0 + (r1 - r0) * s / steps, z0 + (z1 - z0) * s / steps});
  }
  profile.push_back(corners.back());
  constexpr std::uint32_t n = 96;
  Mesh m;
  std::vector<std::uint32_t> rings;
  for (const auto& [r, z] : profile) rings.push_back(ring(m, n, z, [r = r](std::uint32_t) { return r; }));
  for (std::size_t s = 0; s + 1 < rings.size(); ++s) join_rings(m, rings[s], rings[s + 1], n, false);
  // The flat ends: rings inwards every 5 mm, then a centre vertex.
  auto cap = [&](std::uint32_t edge, double r_edge, double z, bool down) {
    std::uint32_t outer_ring = edge;
    for (double r = r_edge - 5.0; r > 2.5; r -= 5.0) {
      const std::uint32_t inner = ring(m, n, z, [r](std::uint32_t) { return r; });
      join_rings(m, inner, outer_ring, n, !down);
      outer_ring = inner;
    }
    const auto c = static_cast<std::uint32_t>(m.vertices.size());
    m.vertices.emplace_back(0.0, 0.0, z);
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::uint32_t j = (i + 1) % n;
      if (down) m.triangles.push_back({c, outer_ring + j, outer_ring + i});
      else m.triangles.push_back({c, outer_ring + i, outer_ring + j});
    }
  };
  cap(rings.front(), corners.front()[0], corners.front()[1], true);
  cap(rings.back(), corners.back()[0], corners.back()[1], false);
  return m;
}

/// A torus lying on the plate: ring radius 70 mm, tube radius 22 mm.
inline Mesh torus() {
  constexpr std::uint32_t nu = 96, nv = 40;
  constexpr double R = 70.0, r = 22.0;
  Mesh m;
  for (std::uint32_t i = 0; i < nu; ++i)
    for (std::uint32_t j = 0; j < nv; ++j) {
      const double u = 2.0 * std::numbers::pi * i / nu, v = 2.0 * std::numbers::pi * j / nv;
      m.vertices.emplace_back((R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u), r + r * std::sin(v));
    }
  for (std::uint32_t i = 0; i < nu; ++i)
    for (std::uint32_t j = 0; j < nv; ++j) {
      const std::uint32_t a = i * nv + j, b = ((i + 1) % nu) * nv + j, c = ((i + 1) % nu) * nv + (j + 1) % nv, d = i * nv + (j + 1) % nv;
      m.triangles.push_back({a, b, c}), m.triangles.push_back({a, c, d});
    }
  return m;
}

/// `m` checked closed and wound outwards (positive volume), scaled to a 200 mm longest side, refined.
inline Mesh finished(Mesh m, const std::string& name, double refine_mm) {
  const planner::EdgeCounts e = planner::count_edges(m);
  double volume = 0.0;
  for (const auto& t : m.triangles) volume += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6.0;
  if (!e.closed() || !(volume > 0.0))
    throw std::logic_error("generated object " + name + ": not a closed mesh wound outwards (" + std::to_string(e.open) +
                           " open edges, " + std::to_string(e.non_manifold) + " non-manifold, volume " + std::to_string(volume) + " mm3)");
  planner::apply_scale(m, planner::fit_scale(m, 200.0));
  return refined(m, refine_mm);
}

}  // namespace generated

/// The generated objects, in name order, made when their turn comes.
inline std::vector<BenchObject> generated_objects(double refine_mm) {
  using Make = planner::TriangleMesh (*)();
  const std::vector<std::pair<std::string, Make>> makers = {{"bracket", generated::bracket}, {"gear", generated::gear},
                                                            {"goblet", generated::goblet},   {"stairs", generated::stairs},
                                                            {"torus", generated::torus}};
  std::vector<BenchObject> out;
  for (const auto& [name, make] : makers)
    out.push_back({name, [name = name, make = make, refine_mm] { return generated::finished(make(), name, refine_mm); }});
  return out;
}

/// Whether `set` names the objects a quality bench can plan (--objects): shared or generated.
inline bool is_object_set(const std::string& set) { return set == "shared" || set == "generated"; }

/// The objects a quality bench plans: "shared", every shared mesh in `meshes_dir` and then the two CAD parts
/// (made at 3 mm), or "generated", the held-out shapes above.
inline std::vector<BenchObject> objects_to_plan(const std::string& set, const std::filesystem::path& meshes_dir, double refine_mm) {
  if (!is_object_set(set)) throw std::invalid_argument("--objects: '" + set + "' is neither shared nor generated");
  if (set == "generated") return generated_objects(refine_mm);
  std::vector<BenchObject> out = shared_mesh_objects(meshes_dir, refine_mm);
  for (auto& obj : cad_objects(3.0, refine_mm)) out.push_back(std::move(obj));
  return out;
}

/// `objects` narrowed to the names in `only` (all of them when it is empty), in their order; throws
/// std::invalid_argument naming every name in `only` that is not one of them.
inline std::vector<BenchObject> only_these(std::vector<BenchObject> objects, const std::set<std::string>& only) {
  if (only.empty()) return objects;
  std::string missing;
  for (const auto& name : only)
    if (std::none_of(objects.begin(), objects.end(), [&](const BenchObject& b) { return b.name == name; }))
      missing += (missing.empty() ? "" : ", ") + name;
  if (!missing.empty()) {
    std::string known;
    for (const auto& b : objects) known += (known.empty() ? "" : ", ") + b.name;
    throw std::invalid_argument("--only: no object named " + missing + " in this set (" + known + ")");
  }
  std::erase_if(objects, [&](const BenchObject& b) { return !only.count(b.name); });
  return objects;
}

}  // namespace scancell::bench
