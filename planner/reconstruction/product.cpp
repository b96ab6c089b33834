#include "planner/reconstruction/product.hpp"

#include <cmath>
#include <sstream>
#include <unordered_set>

#include "common/binary.hpp"
#include "common/errors.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "planner/reconstruction/registration.hpp"

namespace scancell::planner {

std::string cloud_ply(const std::vector<ProductView>& views, std::int64_t job, const ModelSpec& spec,
                      CloudSummary& sum, bool keep_samples, double spacing_mm) {
  if (!(spacing_mm >= 0.0) || !std::isfinite(spacing_mm))
    throw DataError("cloud spacing " + std::to_string(spacing_mm) + " mm: must be >= 0 (0 keeps every sample)");
  sum = CloudSummary{};
  std::string body;
  std::unordered_set<std::uint64_t> taken;  // decimation: occupied cells, 21 bits per axis
  const auto cell_key = [&](const Eigen::Vector3f& p) {
    std::uint64_t key = 0;
    for (int c = 0; c < 3; ++c)
      key = (key << 21) | (static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(p[c] / spacing_mm)) + (1 << 20)) & 0x1FFFFF);
    return key;
  };
  for (const ProductView& v : views) {
    const RangeImage& img = v.image;
    const std::vector<std::uint8_t> ok = MeasuredCoverage::compliant_samples(img, spec);
    const ScanSamples smp = scan_samples(img);  // valid samples in sample order, with normals
    std::size_t k = 0;
    for (std::size_t q = 0; q < img.samples.size(); ++q) {
      if (!img.samples[q].valid()) continue;
      const std::size_t at = k++;
      if (!ok[q]) continue;
      const auto& p = img.samples[q].object_mm;
      const Eigen::Vector3d& n = smp.normals[at];
      ++sum.compliant;
      if (keep_samples) {
        sum.positions.push_back(p.cast<double>());
        sum.normals.push_back(n);
      }
      if (spacing_mm > 0.0 && !taken.insert(cell_key(p)).second) continue;
      for (int c = 0; c < 3; ++c) scancell::append_binary<float>(body, p[c]);
      for (int c = 0; c < 3; ++c) scancell::append_binary<float>(body, static_cast<float>(n[c]));
      scancell::append_binary<float>(body, img.samples[q].sigma_z_mm);
      scancell::append_binary<std::int32_t>(body, v.view);
      scancell::append_binary<std::int32_t>(body, v.round);
      ++sum.points;
    }
    ++sum.views;
  }
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\ncomment scancell registered cloud 1\ncomment job " << job
    << "\ncomment spec precision_mm " << spec.precision_mm << " density_per_mm2 " << spec.density_per_mm2
    << "\ncomment frame object mm";
  if (spacing_mm > 0.0) h << "\ncomment decimated spacing_mm " << spacing_mm << " from " << sum.compliant << " samples";
  h << "\nelement vertex " << sum.points
    << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz"
       "\nproperty float sigma_z_mm\nproperty int view\nproperty int round\nend_header\n";
  return h.str() + body;
}

SurfaceMesh fuse_model(const CloudSummary& cloud, const ModelSpec& spec, ModelSummary& sum) {
  if (cloud.positions.empty())
    throw DataError("fusing a model: no spec-compliant samples (" + std::to_string(cloud.views) + " views, none meets precision " +
                    std::to_string(spec.precision_mm) + " mm and density " + std::to_string(spec.density_per_mm2) + " /mm2)");
  SurfaceMeshOptions o;
  // Half the spec's sample spacing: the surface keeps what the specified density can resolve.
  o.voxel_mm = 0.5 / std::sqrt(spec.density_per_mm2);
  SurfaceMesh m = mesh_from_oriented_points(cloud.positions, cloud.normals, o);
  sum = ModelSummary{};
  sum.vertices = m.mesh.vertices.size();
  sum.triangles = m.mesh.triangles.size();
  sum.voxel_mm = o.voxel_mm;
  sum.boundary_edges = count_edges(m.mesh).open;
  sum.positions = m.mesh.vertices;
  return m;
}

}  // namespace scancell::planner
