#pragma once
// The rough-model sizes a plan or job accepts, header-only and without dependencies, so that scancellctl
// (which links no planner) checks the same range as `scancell plan` and the daemon.
#include <cstddef>

namespace scancell::planner {

/// Rows of the measurability matrix: fewer cannot carry a surface, more outgrow the matrix's memory and plan
/// time.
inline constexpr std::size_t kMinRoughVertices = 50, kMaxRoughVertices = 200000;

}  // namespace scancell::planner
