#pragma once
// What a job hands over (issue 19), built from the journal's stored scans so that it is the same after a
// crash and resume: the registered point cloud of every spec-compliant sample.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "daemon/journal.hpp"
#include "planner/config.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::daemon {

struct CloudSummary {
  std::size_t points = 0;  // spec-compliant samples written
  std::size_t views = 0;   // stored views they come from (the rough scan's and failed registrations excluded)
  std::vector<Eigen::Vector3d> positions, normals;  // the samples written (object frame, mm), when asked for
};

/// A stored view of the job's plan rounds that counts (its registration did not fail), as read back.
struct StoredView {
  planner::RangeImage image;
  int view = 0, round = 0;  // index within its round's plan; round (0, 1, ...)
};

/// Every counting view of `job`'s plan rounds (not the rough scan's), in round and view order.
std::vector<StoredView> load_job_views(Journal& journal, std::int64_t job);

/// `file` (jobs/<id>/cloud.ply): binary little-endian PLY, one vertex per sample that meets the spec
/// (σz ≤ precision, local density ≥ density, thesis eq. 3.4/3.8) in the object frame, as registered and
/// stored: x y z (mm), nx ny nz (unit normal from its image neighbours, towards the scanner; 0 0 0 where a
/// neighbour is missing), sigma_z_mm, view (index within its round's plan), round. Written durably (a
/// reader sees the previous file or the whole new one); rewritten after each round and at the end.
CloudSummary write_job_cloud(const std::vector<StoredView>& views, std::int64_t job, const planner::ModelSpec& spec,
                             const std::filesystem::path& file, bool keep_samples = false);

struct ModelSummary {
  std::size_t vertices = 0, triangles = 0, boundary_edges = 0;  // boundary: edges of the holes left open
  double voxel_mm = 0.0;
  std::vector<Eigen::Vector3d> positions;  // the model's vertices (object frame, mm)
};

/// `file` (jobs/<id>/model.ply): the surface fused from the cloud's samples at a voxel of half the spec's
/// sample spacing, 1/(2√ρ) (planner::mesh_from_oriented_points: OpenVDB sparse field, VolumeToMesh), open
/// where nothing was measured; per-vertex `support`. Written durably.
ModelSummary write_job_model(const CloudSummary& cloud, const planner::ModelSpec& spec, const std::filesystem::path& file);

/// `file` (jobs/<id>/report.json, issue 19): the inspection report. The signed deviation of the cloud's
/// samples and the model's vertices from `reference` (planner::signed_deviation: mean, RMS, 95th percentile
/// and maximum of |d|, share within 3 × the precision spec), with the spec, the reference named and
/// `coverage` (the result's coverage figures) copied in. Written durably; returns the report.
nlohmann::json write_job_report(const std::filesystem::path& file, std::int64_t job, const planner::ModelSpec& spec,
                                const planner::TriangleMesh& reference, const std::string& reference_name,
                                const std::string& reference_kind, const CloudSummary& cloud, const ModelSummary& model,
                                const nlohmann::json& coverage);

}  // namespace scancell::daemon
