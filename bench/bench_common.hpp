#pragma once
// What the benchmarks share: wall time (common/timing.hpp) and the process's peak resident memory.
#include <sys/resource.h>

#include "common/timing.hpp"

namespace scancell::bench {

/// The process's peak resident set so far, MB (getrusage ru_maxrss: an upper bound on any one stage's).
inline double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

}  // namespace scancell::bench
