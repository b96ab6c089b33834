#pragma once
// Limits of a job request that the daemon and its client (scancellctl, header-only, no planner) both check.

namespace scancell::daemon {

/// At most this many setups per job (jobs.max_setups, a submit's `setups`).
inline constexpr int kMaxSetups = 4;

}  // namespace scancell::daemon
