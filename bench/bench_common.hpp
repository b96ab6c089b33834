#pragma once
// What the benchmarks share: wall time (common/timing.hpp) and the process's peak resident memory.
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
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

/// The shipped planner settings, config/planner/default.yaml in the source tree: what a bench plans with
/// unless told otherwise, and the space its oracle is built in (cell_oracle.hpp).
inline std::string shipped_settings_path() { return std::string(SCANCELL_SOURCE_DIR) + "/config/planner/default.yaml"; }

/// A bench's body, run so that an error (a mesh, config or option value it cannot use) is printed with the
/// bench's name and exits 1, rather than ending the process in std::terminate.
template <class Body>
int guarded(const char* name, Body&& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", name, e.what());
    return 1;
  }
}

}  // namespace scancell::bench
