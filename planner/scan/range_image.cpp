#include "planner/scan/range_image.hpp"

#include <optional>

#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "common/binary.hpp"
#include "common/errors.hpp"

namespace scancell::planner {

std::size_t RangeImage::valid_count() const {
  std::size_t n = 0;
  for (const auto& s : samples) n += s.valid();
  return n;
}

SampleCell sample_cell(const RangeImage& img, int i, int j) {
  SampleCell cell;
  const RangeSample& c = img.at(i, j);
  if (!c.valid()) return cell;
  const Eigen::Vector3d centre = c.object_mm.cast<double>();
  // The chord to neighbour (a, b), or none when it lies outside the image or holds no sample.
  auto chord = [&](int a, int b) -> std::optional<Eigen::Vector3d> {
    if (a < 0 || b < 0 || a >= img.columns || b >= img.rows) return std::nullopt;
    const RangeSample& o = img.at(a, b);
    if (!o.valid()) return std::nullopt;
    return o.object_mm.cast<double>() - centre;
  };
  // The mean of the two chords (the minimum would be biased low by the range noise), unless one is a jump
  // (over twice the other): across a depth step the far side says nothing about this surface's sampling.
  // `before` points backwards, so the mean spacing vector is (after − before)/2; its length is the mean of the
  // two chord lengths, as eq. 3.5-3.8 use them.
  struct Spacing {
    Eigen::Vector3d vector;
    double length_mm;
  };
  auto spacing = [](const std::optional<Eigen::Vector3d>& before, const std::optional<Eigen::Vector3d>& after) -> std::optional<Spacing> {
    if (!before && !after) return std::nullopt;
    if (!before) return Spacing{*after, after->norm()};
    if (!after) return Spacing{-*before, before->norm()};
    const double a = before->norm(), b = after->norm();
    if (std::max(a, b) > 2.0 * std::min(a, b)) return a < b ? Spacing{-*before, a} : Spacing{*after, b};
    return Spacing{0.5 * (*after - *before), 0.5 * (a + b)};
  };
  const auto along = spacing(chord(i - 1, j), chord(i + 1, j));
  const auto across = spacing(chord(i, j - 1), chord(i, j + 1));
  if (!along || !across) return cell;
  cell.along_mm = along->vector;
  cell.across_mm = across->vector;
  cell.along_length_mm = along->length_mm;
  cell.across_length_mm = across->length_mm;
  cell.valid = along->length_mm * along->length_mm + across->length_mm * across->length_mm > 0.0;
  return cell;
}

double SampleCell::density_per_mm2() const {
  if (!valid) return 0.0;
  // eq. 3.8 with δx, δy the chord lengths: ρ = 1/(δx² + δy²).
  return 1.0 / (along_length_mm * along_length_mm + across_length_mm * across_length_mm);
}

bool SampleCell::contains(const Eigen::Vector3d& offset_mm, double reach) const {
  if (!valid) return false;
  // Least squares for offset ≈ a·along + b·across (the chords need not be orthogonal on an oblique surface).
  const double aa = along_mm.squaredNorm(), bb = across_mm.squaredNorm(), ab = along_mm.dot(across_mm);
  const double det = aa * bb - ab * ab;
  if (!(det > 1e-12 * aa * bb)) return false;  // collinear chords: no area
  const double pa = along_mm.dot(offset_mm), pb = across_mm.dot(offset_mm);
  const double a = (bb * pa - ab * pb) / det, b = (aa * pb - ab * pa) / det;
  if (std::abs(a) > reach || std::abs(b) > reach) return false;
  const Eigen::Vector3d off_plane = offset_mm - a * along_mm - b * across_mm;
  return off_plane.squaredNorm() <= 0.25 * std::max(aa, bb);
}

double sample_density_per_mm2(const RangeImage& img, int i, int j) { return sample_cell(img, i, j).density_per_mm2(); }

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
T take(const char*& p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  p += sizeof(T);
  return v;
}

}  // namespace

std::string range_image_to_ply(const RangeImage& img) {
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\n";
  h << "comment scancell range image 1\n";
  h << "comment kind " << (img.kind == SensorKind::line_scan ? "line_scan" : "random_access") << "\n";
  h << "comment columns " << img.columns << "\ncomment rows " << img.rows << "\n";
  if (img.job > 0) h << "comment job " << img.job << "\n";
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
  if (!img.truth.empty() && !img.has_truth())
    throw DataError("range image: " + std::to_string(img.truth.size()) + " truth records for " + std::to_string(img.samples.size()) + " samples");
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      if (!s.valid()) continue;
      // Without simulation truth the true point repeats the measured one and the triangle is kNoTriangle.
      const std::size_t at = static_cast<std::size_t>(j) * img.columns + i;
      const SampleTruth t = img.truth.empty() ? SampleTruth{s.object_mm, kNoTriangle} : img.truth[at];
      scancell::append_binary<std::int32_t>(buf, i);
      scancell::append_binary<std::int32_t>(buf, j);
      for (const auto* v : {&s.object_mm, &s.camera_mm, &t.object_mm})
        for (int k = 0; k < 3; ++k) scancell::append_binary<float>(buf, (*v)[k]);
      scancell::append_binary<float>(buf, s.sigma_z_mm);
      scancell::append_binary<std::uint32_t>(buf, t.triangle);
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

namespace {

[[noreturn]] void refuse(const std::string& name, const std::string& why) { throw DataError(name + ": " + why); }

/// What the header said, for the checks after it.
struct RangeHeader {
  bool kind = false, cols = false, rows = false, len = false, pose = false, tag = false, count_given = false;
  std::size_t count = 0, properties = 0;
};

/// One `comment` line: the format tag, kind, columns, rows, scan length or pose, into `img`.
void read_comment(std::istringstream& ls, const std::string& line, const std::string& where, const std::string& name, RangeImage& img,
                  RangeHeader& h) {
  std::string w1;
  ls >> w1;
  if (w1 == "scancell") {
    h.tag = line == "comment scancell range image 1";
    if (!h.tag) refuse(name, where + ": unsupported version");
  } else if (w1 == "kind") {
    std::string k;
    ls >> k;
    if (k == "line_scan") img.kind = SensorKind::line_scan;
    else if (k == "random_access") img.kind = SensorKind::random_access;
    else refuse(name, where + ": unknown kind");
    h.kind = true;
  } else if (w1 == "columns") {
    h.cols = static_cast<bool>(ls >> img.columns) && img.columns >= 2 && img.columns <= 1 << 16;
    if (!h.cols) refuse(name, where + ": columns must be in [2, 65536]");
  } else if (w1 == "rows") {
    h.rows = static_cast<bool>(ls >> img.rows) && img.rows >= 2 && img.rows <= 1 << 16;
    if (!h.rows) refuse(name, where + ": rows must be in [2, 65536]");
  } else if (w1 == "job") {
    if (!(ls >> img.job) || img.job < 1) refuse(name, where + ": the job must be a number >= 1");
  } else if (w1 == "scan_length_mm") {
    h.len = static_cast<bool>(ls >> img.pose.scan_length_mm) && std::isfinite(img.pose.scan_length_mm) && img.pose.scan_length_mm >= 0.0;
    if (!h.len) refuse(name, where + ": bad scan length");
  } else if (w1 == "camera_to_object") {
    Eigen::Matrix4d m;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        if (!(ls >> m(r, c)) || !std::isfinite(m(r, c))) refuse(name, where + ": needs 16 finite numbers");
    const Eigen::Matrix3d rot = m.topLeftCorner<3, 3>();
    if (!(rot.transpose() * rot).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || rot.determinant() < 0.0)
      refuse(name, where + ": rotation part is not a rotation");
    img.pose.camera_to_object.matrix() = m;
    h.pose = true;
  }
}

/// The header (up to `end`) into `img`; refused when a line or a required item is wrong or missing.
RangeHeader read_header(const std::string& data, std::size_t end, const std::string& name, RangeImage& img) {
  std::istringstream header(data.substr(0, end));
  std::string line;
  RangeHeader h;
  std::size_t line_no = 0;
  while (std::getline(header, line)) {
    ++line_no;
    const std::string where = "header line " + std::to_string(line_no) + " '" + line + "'";
    std::istringstream ls(line);
    std::string w0;
    ls >> w0;
    if (line_no == 1) continue;
    if (line_no == 2) {
      if (line != "format binary_little_endian 1.0") refuse(name, where + ": expected binary_little_endian 1.0");
      continue;
    }
    if (w0 == "comment") {
      read_comment(ls, line, where, name, img, h);
    } else if (w0 == "element") {
      std::string kind;
      if (!(ls >> kind >> h.count) || kind != "vertex") refuse(name, where + ": expected 'element vertex N'");
      h.count_given = true;
    } else if (w0 == "property") {
      if (h.properties >= std::size(kProperties) || line != kProperties[h.properties])
        refuse(name, where + ": expected '" + std::string(h.properties < std::size(kProperties) ? kProperties[h.properties] : "end_header") + "'");
      ++h.properties;
    } else {
      refuse(name, where + ": unexpected header line");
    }
  }
  if (!h.tag) refuse(name, "missing 'comment scancell range image 1' (not a scancell range image)");
  if (!h.kind || !h.cols || !h.rows || !h.len || !h.pose || !h.count_given)
    refuse(name, "header lacks one of kind, columns, rows, scan_length_mm, camera_to_object, element vertex");
  if (h.properties != std::size(kProperties))
    refuse(name, "header has " + std::to_string(h.properties) + " of " + std::to_string(std::size(kProperties)) + " properties");
  return h;
}

/// The body's `count` records into the image's pixels; each pixel once, every value finite, simulation truth
/// for all samples or none.
void read_samples(const char* p, std::size_t count, const std::string& name, RangeImage& img) {
  img.samples.assign(static_cast<std::size_t>(img.columns) * img.rows, RangeSample{});
  img.truth.assign(img.samples.size(), SampleTruth{});
  std::size_t with_truth = 0;
  for (std::size_t k = 0; k < count; ++k) {
    const int i = take<std::int32_t>(p), j = take<std::int32_t>(p);
    auto pixel = [&] { return "sample " + std::to_string(k) + ": pixel (" + std::to_string(i) + ", " + std::to_string(j) + ")"; };
    if (i < 0 || j < 0 || i >= img.columns || j >= img.rows) refuse(name, pixel() + " outside the image");
    const std::size_t at = static_cast<std::size_t>(j) * img.columns + i;
    RangeSample& s = img.samples[at];
    SampleTruth& t = img.truth[at];
    if (s.valid()) refuse(name, pixel() + " given twice");
    for (auto* v : {&s.object_mm, &s.camera_mm, &t.object_mm})
      for (int c = 0; c < 3; ++c) (*v)[c] = take<float>(p);
    s.sigma_z_mm = take<float>(p);
    t.triangle = take<std::uint32_t>(p);
    s.measured = true;
    if (!s.object_mm.allFinite() || !s.camera_mm.allFinite() || !t.object_mm.allFinite() || !std::isfinite(s.sigma_z_mm) || s.sigma_z_mm < 0.0f)
      refuse(name, "sample " + std::to_string(k) + ": non-finite or negative value");
    with_truth += t.triangle != kNoTriangle;
  }
  // Simulation truth is all or nothing: a real scanner's file has none, a simulated one has it everywhere.
  if (with_truth != 0 && with_truth != count)
    refuse(name, std::to_string(with_truth) + " of " + std::to_string(count) +
                     " samples carry a triangle id (simulation truth): a file has it for every sample or for none");
  if (with_truth == 0) img.truth.clear();
}

}  // namespace

RangeImage range_image_from_ply(const std::string& data, const std::string& name) {
  const std::size_t end = data.find("end_header\n");
  if (data.rfind("ply\n", 0) != 0 || end == std::string::npos) refuse(name, "not a PLY file (no 'ply' / 'end_header')");
  RangeImage img;
  const RangeHeader h = read_header(data, end, name, img);
  const std::size_t body = end + std::strlen("end_header\n");
  // Checked before any multiplication: a count of 2^62 times the record size wraps around 2^64.
  const std::size_t body_bytes = data.size() - body;
  const std::size_t max_count = static_cast<std::size_t>(img.columns) * static_cast<std::size_t>(img.rows);
  if (h.count > max_count)
    refuse(name, "header: element vertex " + std::to_string(h.count) + " exceeds the image's " + std::to_string(img.columns) + " x " +
                     std::to_string(img.rows) + " pixels");
  if (h.count > body_bytes / kRecordBytes)
    refuse(name, "body has " + std::to_string(body_bytes) + " bytes, too few for " + std::to_string(h.count) + " samples of " +
                     std::to_string(kRecordBytes) + " bytes (truncated?)");
  const std::size_t expect = h.count * kRecordBytes;
  if (body_bytes != expect)
    refuse(name, "body has " + std::to_string(body_bytes) + " bytes, " + std::to_string(h.count) + " samples need " + std::to_string(expect) +
                     " (truncated?)");
  read_samples(data.data() + body, h.count, name, img);
  return img;
}

}  // namespace scancell::planner
