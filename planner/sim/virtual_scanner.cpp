#include "planner/sim/virtual_scanner.hpp"

#include <atomic>
#include <bit>
#include <limits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "planner/errors.hpp"

namespace scancell::planner {

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t a, std::uint64_t b) {
  auto splitmix = [](std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
  };
  return splitmix(splitmix(splitmix(seed) ^ a) ^ (b * 0xD1B54A32D192ED03ull));
}

std::size_t RangeImage::valid_count() const {
  std::size_t n = 0;
  for (const auto& s : samples) n += s.valid();
  return n;
}

RangeImage virtual_scan(const OcclusionScene& scene, const SensorModel& s, const ScanPose& pose,
                        const ScanOptions& options, ScanStats* stats) {
  if (s.kind == SensorKind::line_scan && !(pose.scan_length_mm > 0.0))
    throw std::invalid_argument("virtual_scan: line-scan view needs scan_length_mm > 0");
  RangeImage img;
  img.kind = s.kind;
  img.columns = s.samples_x;
  img.rows = s.samples_y;
  img.pose = pose;
  img.samples.resize(static_cast<std::size_t>(img.columns) * img.rows);

  const Eigen::Matrix3d R = pose.camera_to_object.linear();
  const Eigen::Vector3d T = pose.camera_to_object.translation();
  const double cos_t_xz = std::cos(s.grazing_xz_rad), cos_t_yz = std::cos(s.grazing_yz_rad);
  // Per-column tangent of the laser scan angle; identical for every profile.
  std::vector<double> tan_x(img.columns);
  for (int i = 0; i < img.columns; ++i)
    tan_x[i] = std::tan(-0.5 * s.fov_x_rad + s.fov_x_rad * i / (img.columns - 1));

  std::atomic<std::uint64_t> missed{0}, close{0}, back{0}, grazing{0}, shadow{0}, kept{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, img.rows, 4), [&](const tbb::blocked_range<int>& range) {
    std::vector<OcclusionRay> rays(img.columns), to_receiver;
    std::vector<Hit> hits(img.columns);
    std::vector<int> candidate_column;
    std::vector<Eigen::Vector3d> cam_point, cam_normal;
    std::vector<double> sigma;
    std::vector<std::uint8_t> blocked;
    std::uint64_t c_missed = 0, c_close = 0, c_back = 0, c_grazing = 0, c_shadow = 0, c_kept = 0;
    for (int j = range.begin(); j != range.end(); ++j) {
      Eigen::Vector3d laser = Eigen::Vector3d::Zero();
      double tan_y = 0.0;
      if (s.kind == SensorKind::line_scan) {
        laser.y() = -0.5 * pose.scan_length_mm + pose.scan_length_mm * j / (img.rows - 1);
      } else {
        tan_y = std::tan(-0.5 * s.fov_y_rad + s.fov_y_rad * j / (img.rows - 1));
      }
      const Eigen::Vector3d receiver = laser + Eigen::Vector3d(0.0, s.baseline_mm, 0.0);
      const Eigen::Vector3d laser_obj = R * laser + T, receiver_obj = R * receiver + T;
      for (int i = 0; i < img.columns; ++i) {
        // Direction with unit boresight component: the ray parameter is the range z.
        const Eigen::Vector3d d = R * Eigen::Vector3d(tan_x[i], tan_y, -1.0);
        rays[i] = {laser_obj.cast<float>(), d.cast<float>(), 0.0f, static_cast<float>(s.range_max_mm)};
      }
      scene.first_hits(rays.data(), rays.size(), hits.data());

      candidate_column.clear();
      cam_point.clear();
      cam_normal.clear();
      sigma.clear();
      to_receiver.clear();
      for (int i = 0; i < img.columns; ++i) {
        const Hit& h = hits[i];
        if (h.triangle == kNoHit || (options.object_triangles && h.triangle >= options.object_triangles)) { ++c_missed; continue; }
        const double z = h.t;
        if (z < s.range_min_mm) { ++c_close; continue; }
        const Eigen::Vector3d p(laser.x() + tan_x[i] * z, laser.y() + tan_y * z, -z);
        const Eigen::Vector3d n_obj = h.geometric_normal.normalized();
        const Eigen::Vector3d n = R.transpose() * n_obj;
        if (n.dot(laser - p) <= 0.0 || n.dot(receiver - p) <= 0.0) { ++c_back; continue; }
        // Incidence in the x-z plane against the laser ray, and in the y-z plane (eq. 3.3/3.4).
        const double cos_phi = z / std::sqrt(p.x() * p.x() + z * z);
        const double cos_xz = cos_between(n.x(), n.z(), -(p.x() - laser.x()), z, cos_phi);
        const double cos_yz = s.kind == SensorKind::line_scan ? cos_between(n.y(), n.z(), 0.0, 1.0, 1.0)
                                                              : cos_between(n.y(), n.z(), -(p.y() - laser.y()), z, 1.0);
        if (!(cos_xz > cos_t_xz) || !(cos_yz > cos_t_yz)) { ++c_grazing; continue; }
        const Eigen::Vector3d p_obj = R * p + T;
        const Eigen::Vector3d origin = p_obj + options.ray_offset_mm * n_obj;
        const Eigen::Vector3d to = receiver_obj - origin;
        to_receiver.push_back({origin.cast<float>(), to.cast<float>(), 0.0f, 1.0f});
        candidate_column.push_back(i);
        cam_point.push_back(p);
        cam_normal.push_back(n);
        sigma.push_back(s.noise_cz_per_mm * z * z / cos_yz);
      }
      blocked.assign(to_receiver.size(), 0);
      if (!to_receiver.empty()) scene.occluded(to_receiver.data(), to_receiver.size(), blocked.data());

      // Noise: one stream per (seed, profile), drawn in column order, so the image does not depend on threads.
      std::mt19937_64 rng(mix_seed(options.seed, static_cast<std::uint64_t>(j)));
      std::normal_distribution<double> unit(0.0, 1.0);
      for (std::size_t k = 0; k < candidate_column.size(); ++k) {
        if (blocked[k]) { ++c_shadow; continue; }
        const int i = candidate_column[k];
        const Eigen::Vector3d& p = cam_point[k];
        const double z = -p.z();
        Eigen::Vector3d m = p;
        if (options.noise) {
          m.x() += s.noise_cx * z * unit(rng);
          m.y() += s.noise_cy * z * unit(rng);
          m.z() -= sigma[k] * unit(rng);  // range error along the boresight
        }
        RangeSample& out = img.samples[static_cast<std::size_t>(j) * img.columns + i];
        out.camera_mm = m.cast<float>();
        out.object_mm = (R * m + T).cast<float>();
        out.true_object_mm = (R * p + T).cast<float>();
        out.sigma_z_mm = static_cast<float>(sigma[k]);
        out.triangle = hits[i].triangle;
        ++c_kept;
      }
    }
    missed += c_missed; close += c_close; back += c_back; grazing += c_grazing; shadow += c_shadow; kept += c_kept;
  });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(img.columns) * img.rows;
    stats->missed = missed;
    stats->too_close = close;
    stats->back_facing = back;
    stats->beyond_grazing = grazing;
    stats->receiver_occluded = shadow;
    stats->samples = kept;
  }
  return img;
}

double sample_density_per_mm2(const RangeImage& img, int i, int j) {
  const RangeSample& c = img.at(i, j);
  if (!c.valid()) return 0.0;
  auto chord = [&](int a, int b) {
    if (a < 0 || b < 0 || a >= img.columns || b >= img.rows) return std::numeric_limits<double>::infinity();
    const RangeSample& o = img.at(a, b);
    return o.valid() ? static_cast<double>((o.object_mm - c.object_mm).norm()) : std::numeric_limits<double>::infinity();
  };
  // The mean of the two chords (the minimum would be biased low by the range noise), unless one is a jump
  // (over twice the other): across a depth step the far side says nothing about this surface's sampling.
  auto spacing = [](double a, double b) {
    if (!std::isfinite(a) || !std::isfinite(b)) return std::min(a, b);
    return std::max(a, b) > 2.0 * std::min(a, b) ? std::min(a, b) : 0.5 * (a + b);
  };
  const double dx = spacing(chord(i - 1, j), chord(i + 1, j));
  const double dy = spacing(chord(i, j - 1), chord(i, j + 1));
  if (!std::isfinite(dx) || !std::isfinite(dy)) return 0.0;
  const double d2 = dx * dx + dy * dy;
  return d2 > 0.0 ? 1.0 / d2 : 0.0;
}

// ---------------------------------------------------------------------------------------------------------
// Range image files: binary little-endian PLY with the image's geometry in comments.

namespace {

constexpr const char* kProperties[] = {
    "property int column",        "property int row",          "property float x",     "property float y",
    "property float z",           "property float camera_x",   "property float camera_y", "property float camera_z",
    "property float true_x",      "property float true_y",     "property float true_z",   "property float sigma_z_mm",
    "property uint triangle"};
constexpr std::size_t kRecordBytes = 2 * 4 + 10 * 4 + 4;

template <class T>
void put(std::string& buf, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  buf.append(b, sizeof(T));
}
template <class T>
T take(const char*& p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  p += sizeof(T);
  return v;
}

}  // namespace

std::string range_image_to_ply(const RangeImage& img) {
  static_assert(std::endian::native == std::endian::little, "range image files are little-endian");
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\n";
  h << "comment scancell range image 1\n";
  h << "comment kind " << (img.kind == SensorKind::line_scan ? "line_scan" : "random_access") << "\n";
  h << "comment columns " << img.columns << "\ncomment rows " << img.rows << "\n";
  char num[64];
  std::snprintf(num, sizeof num, "%.17g", img.pose.scan_length_mm);
  h << "comment scan_length_mm " << num << "\ncomment camera_to_object";
  const Eigen::Matrix4d m = img.pose.camera_to_object.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      std::snprintf(num, sizeof num, " %.17g", m(r, c));
      h << num;
    }
  h << "\nelement vertex " << img.valid_count() << "\n";
  for (const char* p : kProperties) h << p << "\n";
  h << "end_header\n";
  std::string buf = h.str();
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      if (!s.valid()) continue;
      put<std::int32_t>(buf, i);
      put<std::int32_t>(buf, j);
      for (const auto* v : {&s.object_mm, &s.camera_mm, &s.true_object_mm})
        for (int k = 0; k < 3; ++k) put<float>(buf, (*v)[k]);
      put<float>(buf, s.sigma_z_mm);
      put<std::uint32_t>(buf, s.triangle);
    }
  return buf;
}

void save_range_image(const RangeImage& img, const std::filesystem::path& path) {
  const std::string buf = range_image_to_ply(img);
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw std::runtime_error(path.string() + ": cannot open for writing");
    f.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    if (!f.flush()) throw std::runtime_error(path.string() + ": write failed");
  }
  std::filesystem::rename(tmp, path);
}

RangeImage load_range_image(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw DataError(path.string() + ": cannot open file");
  const std::string data((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  return range_image_from_ply(data, path.string());
}

RangeImage range_image_from_ply(const std::string& data, const std::string& name) {
  auto fail = [&](const std::string& why) -> void { throw DataError(name + ": " + why); };
  const std::size_t end = data.find("end_header\n");
  if (data.rfind("ply\n", 0) != 0 || end == std::string::npos) fail("not a PLY file (no 'ply' / 'end_header')");
  std::istringstream header(data.substr(0, end));
  std::string line;
  RangeImage img;
  bool have_kind = false, have_cols = false, have_rows = false, have_len = false, have_pose = false, have_tag = false;
  std::size_t count = 0, prop = 0, line_no = 0;
  bool have_count = false;
  while (std::getline(header, line)) {
    ++line_no;
    const std::string where = "header line " + std::to_string(line_no) + " '" + line + "'";
    std::istringstream ls(line);
    std::string w0, w1;
    ls >> w0;
    if (line_no == 1) continue;
    if (line_no == 2) {
      if (line != "format binary_little_endian 1.0") fail(where + ": expected binary_little_endian 1.0");
      continue;
    }
    if (w0 == "comment") {
      ls >> w1;
      if (w1 == "scancell") { have_tag = line == "comment scancell range image 1"; if (!have_tag) fail(where + ": unsupported version"); }
      else if (w1 == "kind") {
        std::string k;
        ls >> k;
        if (k == "line_scan") img.kind = SensorKind::line_scan;
        else if (k == "random_access") img.kind = SensorKind::random_access;
        else fail(where + ": unknown kind");
        have_kind = true;
      } else if (w1 == "columns") { have_cols = static_cast<bool>(ls >> img.columns) && img.columns >= 2 && img.columns <= 1 << 16; if (!have_cols) fail(where + ": columns must be in [2, 65536]"); }
      else if (w1 == "rows") { have_rows = static_cast<bool>(ls >> img.rows) && img.rows >= 2 && img.rows <= 1 << 16; if (!have_rows) fail(where + ": rows must be in [2, 65536]"); }
      else if (w1 == "scan_length_mm") { have_len = static_cast<bool>(ls >> img.pose.scan_length_mm) && std::isfinite(img.pose.scan_length_mm) && img.pose.scan_length_mm >= 0.0; if (!have_len) fail(where + ": bad scan length"); }
      else if (w1 == "camera_to_object") {
        Eigen::Matrix4d m;
        for (int r = 0; r < 4; ++r)
          for (int c = 0; c < 4; ++c)
            if (!(ls >> m(r, c)) || !std::isfinite(m(r, c))) fail(where + ": needs 16 finite numbers");
        const Eigen::Matrix3d rot = m.topLeftCorner<3, 3>();
        if (!(rot.transpose() * rot).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || rot.determinant() < 0.0)
          fail(where + ": rotation part is not a rotation");
        img.pose.camera_to_object.matrix() = m;
        have_pose = true;
      }
      continue;
    }
    if (w0 == "element") {
      std::string kind;
      if (!(ls >> kind >> count) || kind != "vertex") fail(where + ": expected 'element vertex N'");
      have_count = true;
      continue;
    }
    if (w0 == "property") {
      if (prop >= std::size(kProperties) || line != kProperties[prop]) fail(where + ": expected '" + std::string(prop < std::size(kProperties) ? kProperties[prop] : "end_header") + "'");
      ++prop;
      continue;
    }
    fail(where + ": unexpected header line");
  }
  if (!have_tag) fail("missing 'comment scancell range image 1' (not a scancell range image)");
  if (!have_kind || !have_cols || !have_rows || !have_len || !have_pose || !have_count)
    fail("header lacks one of kind, columns, rows, scan_length_mm, camera_to_object, element vertex");
  if (prop != std::size(kProperties)) fail("header has " + std::to_string(prop) + " of " + std::to_string(std::size(kProperties)) + " properties");
  const std::size_t body = end + std::strlen("end_header\n");
  // Checked before any multiplication: a count of 2^62 times the record size wraps around 2^64.
  const std::size_t body_bytes = data.size() - body;
  const std::size_t max_count = static_cast<std::size_t>(img.columns) * static_cast<std::size_t>(img.rows);
  if (count > max_count)
    fail("header: element vertex " + std::to_string(count) + " exceeds the image's " + std::to_string(img.columns) +
         " x " + std::to_string(img.rows) + " pixels");
  if (count > body_bytes / kRecordBytes)
    fail("body has " + std::to_string(body_bytes) + " bytes, too few for " + std::to_string(count) + " samples of " +
         std::to_string(kRecordBytes) + " bytes (truncated?)");
  const std::size_t expect = count * kRecordBytes;
  if (body_bytes != expect)
    fail("body has " + std::to_string(data.size() - body) + " bytes, " + std::to_string(count) + " samples need " + std::to_string(expect) + " (truncated?)");
  img.samples.assign(static_cast<std::size_t>(img.columns) * img.rows, RangeSample{});
  const char* p = data.data() + body;
  for (std::size_t k = 0; k < count; ++k) {
    const int i = take<std::int32_t>(p), j = take<std::int32_t>(p);
    if (i < 0 || j < 0 || i >= img.columns || j >= img.rows)
      fail("sample " + std::to_string(k) + ": pixel (" + std::to_string(i) + ", " + std::to_string(j) + ") outside the image");
    RangeSample& s = img.samples[static_cast<std::size_t>(j) * img.columns + i];
    if (s.valid()) fail("sample " + std::to_string(k) + ": pixel (" + std::to_string(i) + ", " + std::to_string(j) + ") given twice");
    for (auto* v : {&s.object_mm, &s.camera_mm, &s.true_object_mm})
      for (int c = 0; c < 3; ++c) (*v)[c] = take<float>(p);
    s.sigma_z_mm = take<float>(p);
    s.triangle = take<std::uint32_t>(p);
    if (!s.object_mm.allFinite() || !s.camera_mm.allFinite() || !s.true_object_mm.allFinite() || !std::isfinite(s.sigma_z_mm) || s.sigma_z_mm < 0.0f)
      fail("sample " + std::to_string(k) + ": non-finite or negative value");
    if (s.triangle == kNoHit) fail("sample " + std::to_string(k) + ": triangle id is the no-hit marker");
  }
  return img;
}

}  // namespace scancell::planner
