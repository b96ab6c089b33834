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
#include "planner/reconstruction/product.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::daemon {

using planner::CloudSummary;
using planner::ModelSummary;
/// A stored view of the job's plan rounds that counts (its registration did not fail), as read back.
using StoredView = planner::ProductView;

/// Every counting view of `job`'s plan rounds (not the rough scan's), in round and view order.
std::vector<StoredView> load_job_views(Journal& journal, std::int64_t job);

/// `file` (jobs/<id>/cloud.ply): planner::cloud_ply, written durably (a reader sees the previous file or the
/// whole new one); rewritten after each round and at the end.
CloudSummary write_job_cloud(const std::vector<StoredView>& views, std::int64_t job, const planner::ModelSpec& spec,
                             const std::filesystem::path& file, bool keep_samples = false, double spacing_mm = 0.0);

/// `file` (jobs/<id>/model.ply): planner::fuse_model of the cloud (kept with its samples), per-vertex
/// `support`, written durably.
ModelSummary write_job_model(const CloudSummary& cloud, const planner::ModelSpec& spec, const std::filesystem::path& file);

/// `file` (jobs/<id>/report.json, issue 19): the inspection report. The signed deviation of the cloud's
/// samples and the model's vertices from `reference` (planner::signed_deviation: mean, RMS, 95th percentile
/// and maximum of |d|, share within 3 × the precision spec), with the spec, the reference named and
/// `coverage` (the result's coverage figures) copied in. Beside it `deviation.png` (gnuplot): the cloud
/// coloured by signed deviation with its colour bar, titled with the job, reference, date, spec and figures;
/// the report names it (`deviation_png`) or says why it is missing (`deviation_png_error`). Written
/// durably; returns the report.
nlohmann::json write_job_report(const std::filesystem::path& file, std::int64_t job, const planner::ModelSpec& spec,
                                const planner::TriangleMesh& reference, const std::string& reference_name,
                                const std::string& reference_kind, const CloudSummary& cloud, const ModelSummary& model,
                                const nlohmann::json& coverage);

}  // namespace scancell::daemon
