#include "planner/sim/verify.hpp"
#include "common/timing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include <png.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "common/errors.hpp"
#include "planner/core/measurability.hpp"
#include "planner/core/rough_model.hpp"

namespace scancell::planner {
namespace {

/// Sorted cell keys of the compliant samples: a uniform grid with cell = the association radius, so a vertex
/// only looks at its 27 neighbouring cells.
struct SampleGrid {
  double cell = 1.0;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed;  // (cell key, sample index)
  Eigen::AlignedBox3d box;

  static std::uint64_t key(long ix, long iy, long iz) {
    constexpr long kBias = 1L << 20;
    return (static_cast<std::uint64_t>(ix + kBias) << 42) | (static_cast<std::uint64_t>(iy + kBias) << 21) |
           static_cast<std::uint64_t>(iz + kBias);
  }
  long index(double v) const { return static_cast<long>(std::floor(v / cell)); }
};

std::vector<Eigen::Vector3d> face_normals(const TriangleMesh& m) {
  std::vector<Eigen::Vector3d> n(m.triangles.size());
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const auto& t = m.triangles[f];
    n[f] = (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]).normalized();
  }
  return n;
}

/// Fine-model vertices one range image measures: the vertex lies in the cell of a spec-compliant sample (σz,
/// local density; SampleCell), on the vertex's side of the surface. The cells tile what the image sampled,
/// so a vertex counts by the area the compliant samples stand for: at the edge of a sampled region (the
/// frustum's side, a shadow, where incidence crosses the density limit) a fraction of a chord outwards.
/// Before 2026-11-29 any compliant sample within the spec spacing 1/√ρ counted, which credited every such
/// edge with a whole spacing it did not sample: up to 0.04 of m_v on the cell (docs/verification.md).
std::vector<std::uint8_t> vertices_measured(const TriangleMesh& fine, const std::vector<Eigen::Vector3d>& vertex_normals,
                                            const std::vector<Eigen::Vector3d>& tri_normals, const RangeImage& img,
                                            const std::vector<std::uint8_t>& on_boundary, const ModelSpec& spec,
                                            std::size_t* compliant_samples) {
  // Three quarters of a chord, not a half: the range noise moves samples, and the cells of two jittered
  // neighbours would otherwise leave slivers between them. A whole chord at the mesh's own boundary (an open
  // sheet's rim): nothing lies beyond it to sample, and samples within the sample spacing of the end of a
  // surface have measured up to it.
  constexpr double kCellReach = 0.75, kBoundaryReach = 1.0;
  const std::size_t nv = fine.vertices.size();
  // The side test below reads the triangle each sample hit: simulation truth (callers check it is there).
  if (!img.has_truth()) throw DataError("verification needs the simulated scanner's truth for every sample");
  // A compliant cell has δx² + δy² ≤ 1/ρ, so it reaches at most (δx + δy) ≤ √(2/ρ) from its sample: the 27
  // grid cells of side √2/√ρ around a vertex hold every cell that can contain it.
  const double radius = std::sqrt(2.0 / spec.density_per_mm2);
  SampleGrid grid;
  grid.cell = radius;
  std::vector<SampleCell> cells(img.samples.size());  // set for the compliant samples only
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      if (!s.valid() || s.sigma_z_mm > spec.precision_mm) continue;
      const SampleCell cell = sample_cell(img, i, j);
      if (cell.density_per_mm2() < spec.density_per_mm2) continue;
      const std::uint32_t idx = static_cast<std::uint32_t>(j) * img.columns + i;
      cells[idx] = cell;
      const Eigen::Vector3d p = s.object_mm.cast<double>();
      grid.keyed.emplace_back(SampleGrid::key(grid.index(p.x()), grid.index(p.y()), grid.index(p.z())), idx);
      grid.box.extend(p);
    }
  if (compliant_samples) *compliant_samples = grid.keyed.size();
  std::sort(grid.keyed.begin(), grid.keyed.end());

  std::vector<std::uint8_t> hit(nv, 0);
  if (grid.keyed.empty()) return hit;
  Eigen::AlignedBox3d reach = grid.box;
  reach.min().array() -= radius;
  reach.max().array() += radius;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t v = r.begin(); v != r.end(); ++v) {
      const Eigen::Vector3d& p = fine.vertices[v];
      if (!reach.contains(p)) continue;
      const double cell_reach = on_boundary[v] ? kBoundaryReach : kCellReach;
      const long cx = grid.index(p.x()), cy = grid.index(p.y()), cz = grid.index(p.z());
      bool found = false;
      for (long dx = -1; dx <= 1 && !found; ++dx)
        for (long dy = -1; dy <= 1 && !found; ++dy)
          for (long dz = -1; dz <= 1 && !found; ++dz) {
            const std::uint64_t key = SampleGrid::key(cx + dx, cy + dy, cz + dz);
            auto it = std::lower_bound(grid.keyed.begin(), grid.keyed.end(), std::make_pair(key, std::uint32_t{0}));
            for (; it != grid.keyed.end() && it->first == key; ++it) {
              if (!cells[it->second].contains(p - img.samples[it->second].object_mm.cast<double>(), cell_reach)) continue;
              // The sample must lie on the vertex's side of the surface (thin walls, sheet edges).
              if (tri_normals[img.truth[it->second].triangle].dot(vertex_normals[v]) <= 0.0) continue;
              found = true;
              break;
            }
          }
      hit[v] = found;
    }
  });
  return hit;
}

/// Each fine vertex's share of the area (a third of each adjacent triangle) and the total.
void share_area(const TriangleMesh& fine, Verification& out) {
  out.vertex_area_mm2.assign(fine.vertices.size(), 0.0);
  for (const auto& t : fine.triangles) {
    const double a = triangle_area(fine, t) / 3.0;
    for (int k = 0; k < 3; ++k) out.vertex_area_mm2[t[k]] += a;
  }
  for (double a : out.vertex_area_mm2) out.area_mm2 += a;
}


/// The fine model as verification reads it (area shares, vertex and face normals, its open rim) and the tally
/// of what the executed views measured of it, view by view in order: each view's area alone, its gain, the
/// cumulative m_v. Both verify_views (the plan executed here) and verify_images (images a job stored) count so.
class FineTally {
 public:
  FineTally(const TriangleMesh& fine, Verification& out)
      : fine_(fine), out_(out), vertex_normals_(area_weighted_normals(fine)), tri_normals_(face_normals(fine)),
        on_boundary_(open_edge_vertices(fine)) {
    share_area(fine, out);
    out.measured.assign(fine.vertices.size(), 0);
  }

  /// The fine vertices `img` measures (vertices_measured).
  std::vector<std::uint8_t> measured_by(const RangeImage& img, const ModelSpec& spec, std::size_t* compliant_samples) const {
    return vertices_measured(fine_, vertex_normals_, tri_normals_, img, on_boundary_, spec, compliant_samples);
  }

  /// Counts the next view's `hit` vertices into `vv` (alone, gain, cumulative) and `out.measured`; `ids`,
  /// when given, receives them.
  void count(ViewVerification& vv, const std::vector<std::uint8_t>& hit, std::vector<std::uint32_t>* ids = nullptr) {
    for (std::size_t v = 0; v < hit.size(); ++v) {
      if (!hit[v]) continue;
      if (ids) ids->push_back(static_cast<std::uint32_t>(v));
      vv.alone_mm2 += out_.vertex_area_mm2[v];
      if (!out_.measured[v]) {
        out_.measured[v] = 1;
        vv.gain_mm2 += out_.vertex_area_mm2[v];
      }
    }
    cumulative_ += vv.gain_mm2;
    vv.cumulative = out_.area_mm2 > 0.0 ? cumulative_ / out_.area_mm2 : 0.0;
  }

 private:
  const TriangleMesh& fine_;
  Verification& out_;
  const std::vector<Eigen::Vector3d> vertex_normals_, tri_normals_;
  const std::vector<std::uint8_t> on_boundary_;
  double cumulative_ = 0.0;
};

}  // namespace

Verification verify_views(const TriangleMesh& fine, const SensorModel& sensor, const ModelSpec& spec,
                          const std::vector<ScanPose>& views, const std::vector<double>& estimated_cumulative,
                          const VerifyOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  Verification out;
  FineTally tally(fine, out);
  TriangleMesh scene_mesh = fine;
  append_mesh(scene_mesh, options.occluders);
  const OcclusionScene scene(scene_mesh);

  std::vector<std::vector<std::uint32_t>> measured_by(views.size());
  std::vector<std::uint16_t> times_measured(fine.vertices.size(), 0);
  out.views.resize(views.size());
  for (std::size_t k = 0; k < views.size(); ++k) {
    ViewVerification& vv = out.views[k];
    vv.executed = sample_pose_error(views[k], options.pose_error, mix_seed(options.pose_seed, k, 1));
    ScanOptions so;
    so.seed = mix_seed(options.seed, k, 0);
    so.noise = options.noise;
    so.ray_offset_mm = options.ray_offset_mm;
    so.object_triangles = options.occluders.triangles.empty() ? 0 : fine.triangles.size();
    const RangeImage img = virtual_scan(scene, sensor, vv.executed, so, &vv.scan);

    tally.count(vv, tally.measured_by(img, spec, &vv.compliant_samples), &measured_by[k]);
    for (auto v : measured_by[k]) ++times_measured[v];
    vv.cumulative_estimated = k < estimated_cumulative.size() ? estimated_cumulative[k] : std::nan("");
  }
  for (std::size_t k = 0; k < views.size(); ++k)
    for (auto v : measured_by[k])
      if (times_measured[v] == 1) out.views[k].unique_mm2 += out.vertex_area_mm2[v];
  out.mv = views.empty() ? 0.0 : out.views.back().cumulative;
  out.estimated = estimated_cumulative.empty() ? std::nan("") : estimated_cumulative.back();

  if (options.analytic && !views.empty()) {
    // The analytic test of the planner, evaluated on the fine mesh at the executed poses.
    const RoughModel fine_rows = make_rough_model(fine);
    TriangleMesh rows_mesh = fine_rows.mesh();
    append_mesh(rows_mesh, options.occluders);
    const OcclusionScene rows_scene(rows_mesh);
    std::vector<Viewpoint> vps;
    for (const auto& vv : out.views)
      vps.push_back(viewpoint_from_pose(vv.executed.camera_to_object.linear(), vv.executed.camera_to_object.translation(),
                                        vv.executed.scan_length_mm));
    const MeasurabilityMatrix m = build_measurability(fine_rows, rows_scene, sensor, spec, vps);
    std::vector<std::uint8_t> covered(fine_rows.size(), 0);
    double area = 0.0;
    for (std::size_t k = 0; k < vps.size(); ++k) {
      m.columns[k].for_each([&](std::uint32_t r) {
        if (!covered[r]) {
          covered[r] = 1;
          area += fine_rows.area_mm2[r];
        }
      });
      out.views[k].cumulative_analytic = fine_rows.total_area_mm2 > 0.0 ? area / fine_rows.total_area_mm2 : 0.0;
    }
    out.mv_analytic = out.views.back().cumulative_analytic;
  }
  out.seconds = seconds_since(t0);
  return out;
}

Verification verify_images(const TriangleMesh& fine, const ModelSpec& spec, const std::vector<RangeImage>& images) {
  const auto t0 = std::chrono::steady_clock::now();
  Verification out;
  FineTally tally(fine, out);
  for (std::size_t k = 0; k < images.size(); ++k) {
    const RangeImage& im = images[k];
    if (!im.has_truth())
      throw DataError("scan " + std::to_string(k) + " has no simulation truth (a real scanner's image?): verification against the "
                      "fine model needs the triangle each sample hit, which only the virtual scanner records");
    for (std::size_t q = 0; q < im.samples.size(); ++q)
      if (im.samples[q].valid() && im.truth[q].triangle >= fine.triangles.size())
        throw DataError("scan " + std::to_string(k) + ": triangle id " + std::to_string(im.truth[q].triangle) +
                        " beyond the fine model's " + std::to_string(fine.triangles.size()) + " (not a scan of this model)");
    ViewVerification vv;
    vv.executed = images[k].pose;
    tally.count(vv, tally.measured_by(images[k], spec, &vv.compliant_samples));
    vv.cumulative_estimated = std::nan("");
    out.views.push_back(vv);
  }
  out.mv = out.views.empty() ? 0.0 : out.views.back().cumulative;
  out.estimated = std::nan("");
  out.seconds = seconds_since(t0);
  return out;
}

MonteCarloResult verify_monte_carlo(const TriangleMesh& fine, const SensorModel& sensor, const ModelSpec& spec,
                                    const std::vector<ScanPose>& views, const VerifyOptions& options, int trials) {
  if (trials < 1) throw std::invalid_argument("verify_monte_carlo: trials must be >= 1");
  const auto t0 = std::chrono::steady_clock::now();
  MonteCarloResult r;
  VerifyOptions o = options;
  o.analytic = false;
  for (int t = 0; t < trials; ++t) {
    o.pose_seed = mix_seed(options.pose_seed, static_cast<std::uint64_t>(t), 7);
    r.mv.push_back(verify_views(fine, sensor, spec, views, {}, o).mv);
  }
  double s = 0.0, s2 = 0.0;
  for (double m : r.mv) s += m, s2 += m * m;
  r.mean = s / trials;
  r.sd = trials > 1 ? std::sqrt(std::max(0.0, (s2 - trials * r.mean * r.mean) / (trials - 1))) : 0.0;
  r.min = *std::min_element(r.mv.begin(), r.mv.end());
  r.max = *std::max_element(r.mv.begin(), r.mv.end());
  r.seconds = seconds_since(t0);
  return r;
}

std::string verification_summary(const Verification& v) {
  std::ostringstream os;
  char buf[256];
  os << " view  samples  compliant  alone_mm2  gain_mm2  unique_mm2  m_v_cum  m_analytic_cum  m_est_cum  est-ver\n";
  for (std::size_t k = 0; k < v.views.size(); ++k) {
    const auto& w = v.views[k];
    std::snprintf(buf, sizeof buf, " %4zu  %7llu  %9zu  %9.1f  %8.1f  %10.1f  %7.4f  %14.4f  %9.4f  %+7.4f\n", k,
                  static_cast<unsigned long long>(w.scan.samples), w.compliant_samples, w.alone_mm2, w.gain_mm2,
                  w.unique_mm2, w.cumulative, w.cumulative_analytic, w.cumulative_estimated,
                  w.cumulative_estimated - w.cumulative);
    os << buf;
  }
  std::snprintf(buf, sizeof buf,
                "views: %zu  fine area: %.1f mm2  verified m_v: %.4f  analytic m_v: %.4f  estimated: %.4f  "
                "estimated - verified: %+.4f  (%.2f s)\n",
                v.views.size(), v.area_mm2, v.mv, v.mv_analytic, v.estimated, v.estimated - v.mv, v.seconds);
  os << buf;
  return os.str();
}

void write_coverage_ply(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                        const std::filesystem::path& path) {
  if (measured.size() != mesh.vertices.size()) throw std::invalid_argument("write_coverage_ply: one flag per vertex");
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::trunc);
    if (!f) throw std::runtime_error(path.string() + ": cannot open for writing");
    f << "ply\nformat ascii 1.0\ncomment scancell coverage: grey = measured to spec, red = not (units mm)\n"
      << "element vertex " << mesh.vertices.size()
      << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
         "property uchar blue\nproperty uchar measured\nelement face "
      << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    char buf[160];
    for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
      const auto& p = mesh.vertices[i];
      const bool m = measured[i];
      std::snprintf(buf, sizeof buf, "%.5f %.5f %.5f %d %d %d %d\n", p.x(), p.y(), p.z(), m ? 200 : 220, m ? 200 : 40,
                    m ? 200 : 40, m ? 1 : 0);
      f << buf;
    }
    for (const auto& t : mesh.triangles) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
    if (!f.flush()) throw std::runtime_error(path.string() + ": write failed");
  }
  std::filesystem::rename(tmp, path);
}

void write_measurability_png(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                             const std::filesystem::path& path, int tile) {
  if (measured.size() != mesh.vertices.size()) throw std::invalid_argument("write_measurability_png: one flag per vertex");
  if (tile < 16 || tile > 4096) throw std::invalid_argument("write_measurability_png: tile size out of range");
  const OcclusionScene scene(mesh);
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(v);
  const Eigen::Vector3d c = box.center();
  const double half = 0.55 * box.sizes().maxCoeff();
  const double far = 4.0 * half + 1.0;
  const int cols = 3, rows = 2, width = cols * tile, height = rows * tile;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(width) * height * 3, 0);
  // From +X, -X, +Y, -Y, +Z, -Z: each tile looks back along -d with image axes (e1 right, e2 up).
  const Eigen::Vector3d dirs[6] = {Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                   -Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), -Eigen::Vector3d::UnitZ()};
  tbb::parallel_for(0, 6, [&](int t) {
    const Eigen::Vector3d d = dirs[t];
    const Eigen::Vector3d up = std::abs(d.z()) > 0.5 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d e1 = up.cross(d).normalized(), e2 = d.cross(e1);
    const int ox = (t % cols) * tile, oy = (t / cols) * tile;
    std::vector<OcclusionRay> rays(tile);
    std::vector<Hit> hits(tile);
    for (int py = 0; py < tile; ++py) {
      for (int px = 0; px < tile; ++px) {
        const double u = (2.0 * (px + 0.5) / tile - 1.0) * half, v = (1.0 - 2.0 * (py + 0.5) / tile) * half;
        const Eigen::Vector3d o = c + far * d + u * e1 + v * e2;
        rays[px] = {o.cast<float>(), (-d).cast<float>(), 0.0f, static_cast<float>(2.0 * far)};
      }
      scene.first_hits(rays.data(), rays.size(), hits.data());
      for (int px = 0; px < tile; ++px) {
        std::uint8_t* out = &rgb[(static_cast<std::size_t>(oy + py) * width + ox + px) * 3];
        const Hit& h = hits[px];
        if (h.triangle == kNoHit) {
          out[0] = 36; out[1] = 40; out[2] = 48;
          continue;
        }
        const auto& tri = mesh.triangles[h.triangle];
        const double m = (1.0 - h.u - h.v) * measured[tri[0]] + h.u * measured[tri[1]] + h.v * measured[tri[2]];
        const double shade = 0.35 + 0.65 * std::abs(h.geometric_normal.normalized().dot(d));
        const double r = (220 * (1 - m) + 205 * m) * shade, g = (40 * (1 - m) + 205 * m) * shade,
                     b = (40 * (1 - m) + 205 * m) * shade;
        out[0] = static_cast<std::uint8_t>(r);
        out[1] = static_cast<std::uint8_t>(g);
        out[2] = static_cast<std::uint8_t>(b);
      }
    }
  });
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = width;
  img.height = height;
  img.format = PNG_FORMAT_RGB;
  const std::string tmp = path.string() + ".tmp";
  if (!png_image_write_to_file(&img, tmp.c_str(), 0, rgb.data(), width * 3, nullptr))
    throw std::runtime_error(path.string() + ": PNG write failed: " + img.message);
  std::filesystem::rename(tmp, path);
}

}  // namespace scancell::planner
