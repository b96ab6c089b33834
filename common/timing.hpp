#pragma once
// Wall-clock seconds on the monotonic clock, for the durations plans, jobs and benchmarks report.
#include <chrono>

namespace scancell {

inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace scancell
