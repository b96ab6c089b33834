#pragma once
// Disjoint sets with path halving: the registration graph's components (cover.cpp, local_cover.cpp).
#include <cstdint>
#include <numeric>
#include <vector>

namespace scancell::planner {

struct UnionFind {
  std::vector<std::uint32_t> p;
  explicit UnionFind(std::size_t n) : p(n) { std::iota(p.begin(), p.end(), 0u); }
  std::uint32_t find(std::uint32_t x) {
    while (p[x] != x) x = p[x] = p[p[x]];
    return x;
  }
  void unite(std::uint32_t a, std::uint32_t b) { p[find(a)] = find(b); }
};

}  // namespace scancell::planner
