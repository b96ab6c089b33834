#pragma once
// What a job hands over (issue 19), built from the journal's stored scans so that it is the same after a
// crash and resume: the registered point cloud of every spec-compliant sample.
#include <cstdint>
#include <filesystem>
#include <string>

#include "daemon/journal.hpp"
#include "planner/config.hpp"

namespace scancell::daemon {

struct CloudSummary {
  std::size_t points = 0;  // spec-compliant samples written
  std::size_t views = 0;   // stored views they come from (the rough scan's and failed registrations excluded)
};

/// `file` (jobs/<id>/cloud.ply): binary little-endian PLY, one vertex per sample that meets the spec
/// (σz ≤ precision, local density ≥ density, thesis eq. 3.4/3.8) in the object frame, as registered and
/// stored: x y z (mm), nx ny nz (unit normal from its image neighbours, towards the scanner; 0 0 0 where a
/// neighbour is missing), sigma_z_mm, view (index within its round's plan), round. Written durably (a
/// reader sees the previous file or the whole new one); rewritten after each round and at the end.
CloudSummary write_job_cloud(Journal& journal, std::int64_t job, const planner::ModelSpec& spec,
                             const std::filesystem::path& file);

}  // namespace scancell::daemon
