#include "daemon/job_result.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "daemon/job_product.hpp"
#include "planner/sim/verify.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;
using nlohmann::json;

RowTally tally_unmeasured(const sp::RoughModel& rough, const std::vector<std::uint32_t>& unmeasured,
                          const std::vector<std::uint32_t>& unmeasurable) {
  std::vector<std::uint8_t> impossible(rough.size(), 0);
  for (auto r : unmeasurable) impossible[r] = 1;
  RowTally t;
  for (auto r : unmeasured) {
    const double a = rough.area_mm2[r];
    const bool guess = !rough.hypothetical.empty() && rough.hypothetical[r];
    t.unmeasured_area += a;
    if (guess) {
      ++t.hypothetical;
      t.hypothetical_area += a;
    }
    if (impossible[r]) {
      t.impossible_area += a;
    } else if (guess) {
      ++t.guessed;
      t.guessed_area += a;
    } else {
      ++t.open;
      t.open_area += a;
    }
  }
  return t;
}

std::vector<std::uint32_t> held_rows(const json& info) {
  if (!info.contains("view_rows") || !info.contains("excused_rows") || info.at("excused_rows").empty())
    return info.value("predicted_rows", std::vector<std::uint32_t>{});
  const auto& per_view = info.at("view_rows");
  const auto& excused = info.at("excused_rows");
  std::vector<std::uint32_t> held;
  for (std::size_t v = 0; v < per_view.size(); ++v) {
    auto rows = per_view[v].get<std::vector<std::uint32_t>>();
    const auto ex = excused.find(std::to_string(v));
    if (ex != excused.end()) {
      auto skip = ex->get<std::vector<std::uint32_t>>();
      std::sort(skip.begin(), skip.end());
      rows.erase(std::remove_if(rows.begin(), rows.end(), [&](std::uint32_t r) { return std::binary_search(skip.begin(), skip.end(), r); }),
                 rows.end());
    }
    held.insert(held.end(), rows.begin(), rows.end());
  }
  std::sort(held.begin(), held.end());
  held.erase(std::unique(held.begin(), held.end()), held.end());
  return held;
}

std::vector<std::uint8_t> failure_counts(const std::vector<json>& round_infos, const std::vector<std::uint8_t>& measured) {
  std::vector<std::uint8_t> fails(measured.size(), 0);
  for (const auto& info : round_infos)
    for (const auto row : held_rows(info))
      if (row < fails.size() && !measured[row] && fails[row] < 255) ++fails[row];
  return fails;
}

std::vector<std::uint8_t> given_up_rows(const std::vector<json>& round_infos, const std::vector<std::uint8_t>& measured,
                                        double measured_now, int retire_after, double total_mm2) {
  const std::vector<std::uint8_t> fails = failure_counts(round_infos, measured);
  std::vector<std::uint8_t> out(fails.size(), 0);
  for (std::size_t r = 0; r < fails.size(); ++r) out[r] = fails[r] >= retire_after;
  if (replan_fell_short(round_infos, measured_now, total_mm2))
    for (const auto row : held_rows(round_infos.back()))
      if (row < out.size() && !measured[row]) out[row] = 1;
  return out;
}

bool replan_fell_short(const std::vector<json>& round_infos, double measured_now, double total_mm2) {
  if (round_infos.size() < 2) return false;
  const json& last = round_infos.back();
  return measured_now <= last.value("measured_before", 0.0) + 1e-9 ||
         round_gains({last}, measured_now, total_mm2).back().at("under_20_percent").get<bool>();
}

json round_gains(const std::vector<json>& round_infos, double measured_now, double total_mm2) {
  json out = json::array();
  for (std::size_t k = 0; k < round_infos.size(); ++k) {
    const json& info = round_infos[k];
    const double before = info.value("measured_before", 0.0);
    const double after = k + 1 < round_infos.size() ? round_infos[k + 1].value("measured_before", measured_now) : measured_now;
    const double predicted = info.value("predicted_gain_mm2", 0.0), realized = (after - before) * total_mm2;
    out.push_back({{"round", info.value("round", static_cast<int>(k))},
                   {"views", info.value("views", 0)},
                   {"predicted_gain_mm2", predicted},
                   {"realized_gain_mm2", realized},
                   {"realized_share", predicted > 0.0 ? realized / predicted : 0.0},
                   {"under_20_percent", predicted > 0.0 && realized < 0.2 * predicted}});
  }
  return out;
}

std::filesystem::path write_unmeasured_rows(const sp::RoughModel& rough, const std::vector<std::uint32_t>& rows,
                                            const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  const auto path = dir / "unmeasured.xyz";
  std::ofstream f(path);
  f << "# rough-model rows not measured to the spec: x y z (mm, object frame) nx ny nz area_mm2\n";
  for (auto r : rows) {
    const auto& p = rough.points[r];
    const auto& n = rough.normals[r];
    f << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << n.x() << ' ' << n.y() << ' ' << n.z() << ' ' << rough.area_mm2[r] << "\n";
  }
  return path;
}

json closed_loop_account(const sp::RoughModel& rough, const std::vector<json>& round_infos,
                         const std::vector<std::uint8_t>& measured, double measured_now, int retire_after,
                         const std::filesystem::path& dir) {
  json out;
  const json gains = round_gains(round_infos, measured_now, rough.total_area_mm2);
  json weak = json::array();
  for (const auto& g : gains)
    if (g.at("under_20_percent").get<bool>()) weak.push_back(g.at("round"));
  out["round_gains"] = gains;
  out["rounds_under_20_percent"] = weak;
  const auto fails = failure_counts(round_infos, measured);
  const auto given_up = given_up_rows(round_infos, measured, measured_now, retire_after, rough.total_area_mm2);
  std::size_t n = 0;
  double area = 0.0;
  std::filesystem::create_directories(dir);
  const auto attention = dir / "needs_attention.xyz";
  std::ofstream fa(attention);
  fa << "# rows predicted measurable by " << retire_after
     << " or more executed rounds, or by a replanning round that measured nothing new, and still unmeasured:"
        " x y z (mm, object frame) nx ny nz area_mm2 rounds_failed\n";
  for (std::size_t r = 0; r < fails.size(); ++r)
    if (given_up[r]) {
      ++n;
      area += rough.area_mm2[r];
      const auto& p = rough.points[r];
      const auto& nn = rough.normals[r];
      fa << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << nn.x() << ' ' << nn.y() << ' ' << nn.z() << ' '
         << rough.area_mm2[r] << ' ' << int(fails[r]) << "\n";
    }
  out["needs_attention_rows"] = n;
  out["needs_attention_area_mm2"] = area;
  out["needs_attention_file"] = attention.string();
  return out;
}

namespace {

/// The coverage of the rough model from the true hit points of the samples the daemon counted as compliant
/// (their density from the stored, noisy positions), each dropped when it lies farther than 3 × the precision
/// spec from the true surface along its normal: a slide along the surface does not make the data wrong, a
/// step off it does. How far registration (or its absence) lets the measured figure be trusted.
json truth_coverage(const std::vector<sp::RangeImage>& images, const sp::RoughModel& rough, const sp::ModelSpec& spec,
                    const sp::CoverageOptions& coverage, const sp::TriangleMesh& fine) {
  sp::MeasuredCoverage truth(rough, spec, coverage);
  const double tolerance = 3.0 * spec.precision_mm;
  double ss = 0.0, ssn = 0.0;
  std::size_t n = 0, nn = 0, off = 0;
  for (auto img : images) {
    std::vector<std::uint8_t> compliant = sp::MeasuredCoverage::compliant_samples(img, spec);
    for (std::size_t k = 0; k < img.samples.size(); ++k) {
      auto& smp = img.samples[k];
      if (!smp.valid()) continue;
      const sp::SampleTruth& truth_k = img.truth[k];
      const Eigen::Vector3d e = (smp.object_mm - truth_k.object_mm).cast<double>();
      ss += e.squaredNorm();
      ++n;
      smp.object_mm = truth_k.object_mm;
      if (truth_k.triangle >= fine.triangles.size()) continue;  // the plate
      const auto& t = fine.triangles[truth_k.triangle];
      const Eigen::Vector3d normal =
          (fine.vertices[t[1]] - fine.vertices[t[0]]).cross(fine.vertices[t[2]] - fine.vertices[t[0]]).normalized();
      const double en = std::abs(e.dot(normal));
      ssn += en * en;
      ++nn;
      if (en > tolerance) {
        compliant[k] = 0;
        ++off;
      }
    }
    truth.add(img, &compliant);
  }
  // How far the stored samples are from the surface points the laser really hit (pose error left after
  // registration, plus range noise): in 3-D, across the true surface, and the share farther across it than
  // the tolerance.
  return {{"verified_coverage", truth.coverage()},
          {"sample_error_rms_mm", n ? std::sqrt(ss / static_cast<double>(n)) : 0.0},
          {"sample_normal_error_rms_mm", nn ? std::sqrt(ssn / static_cast<double>(nn)) : 0.0},
          {"samples_off_spec", nn ? static_cast<double>(off) / static_cast<double>(nn) : 0.0}};
}

}  // namespace

json simulation_truth_checks(const std::vector<sp::RangeImage>& images, const sp::RoughModel* rough, const sp::ModelSpec& spec,
                             const sp::CoverageOptions& coverage, const sp::TriangleMesh& truth, const std::string& truth_name,
                             const std::filesystem::path& dir) {
  json out = json::object();
  if (rough) out = truth_coverage(images, *rough, spec, coverage, truth);
  // Verified measurability of the stored scans against the object actually on the table.
  const sp::Verification v = sp::verify_images(truth, spec, images);
  out["verified_mv"] = v.mv;
  out["verified_against"] = truth_name;
  std::filesystem::create_directories(dir);
  char title[512];
  std::snprintf(title, sizeof title,
                "coverage of %s by %zu views\nverified m_v %.4f of %.0f mm² (virtual scanner, object on the table), "
                "spec %g mm, %g samples/mm²",
                std::filesystem::path(truth_name).filename().c_str(), images.size(), v.mv, v.area_mm2, spec.precision_mm,
                spec.density_per_mm2);
  // Without gnuplot the picture is the bare six views: said, not hidden.
  if (const std::string why = sp::write_coverage_picture(truth, v.measured, title, dir / "coverage.png"); !why.empty())
    out["coverage_png_error"] = why;
  sp::write_coverage_ply(truth, v.measured, (dir / "coverage.ply").string());
  out["coverage_png"] = (dir / "coverage.png").string();
  out["coverage_ply"] = (dir / "coverage.ply").string();
  return out;
}

}  // namespace scancell::daemon
