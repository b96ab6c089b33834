#pragma once
#include <csignal>
// `scancell-sim scanner`: a GigE Vision line scanner on its own, beside the simulated drives (issue 18).

namespace scancell::tools {

/// Runs the scanner until SIGINT/SIGTERM; returns the exit code (2: usage, 1: could not start).
int serve_scanner(int argc, char** argv, const volatile std::sig_atomic_t& stop);

}  // namespace scancell::tools
