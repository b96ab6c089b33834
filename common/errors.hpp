#pragma once
// Errors raised on bad input. Each names what was wrong and where (file, element, key path),
// so the command line can print it and exit non-zero without a crash.
#include <stdexcept>
#include <string>

namespace scancell {

/// A mesh file that cannot be used: unreadable, malformed, or without usable triangles.
struct MeshError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// A configuration file or value that is missing, malformed or out of range; the message carries the key path.
struct ConfigError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// A data file (plan, range image) that is malformed, truncated or inconsistent; the message names the file
/// and the element.
struct DataError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Planning stopped because its caller asked (plan_views' `cancel` flag turned non-zero): the message names
/// the stage it stopped at. Nothing of the plan is kept.
struct PlanCancelled : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace scancell
