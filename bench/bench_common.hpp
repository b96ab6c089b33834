#pragma once
// What the benchmarks share: wall time (common/timing.hpp) and the process's peak resident memory.
#include <sys/resource.h>

#include <cstdlib>
#include <iostream>
#include <string>

#include "common/timing.hpp"

namespace scancell::bench {

/// The process's peak resident set so far, MB (getrusage ru_maxrss: an upper bound on any one stage's).
inline double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

/// The value after the option at argv[i], i advanced past it; without one, exit 2 naming the option.
inline std::string option_value(int argc, char** argv, int& i) {
  if (i + 1 >= argc) {
    std::cerr << argv[i] << " needs a value\n";
    std::exit(2);
  }
  return argv[++i];
}

}  // namespace scancell::bench
