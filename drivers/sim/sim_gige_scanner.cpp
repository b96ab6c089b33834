#include "drivers/sim/sim_gige_scanner.hpp"

#include <arv.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>

#include "drivers/axis.hpp"
#include "drivers/genicam/genicam_xml.hpp"  // generated

namespace scancell::drivers {

namespace {

// GigE Vision bootstrap registers (GigE Vision 2.0, table 28-1): the user-defined name, 16 bytes.
constexpr std::uint32_t kUserNameRegister = 0x00E8, kUserNameSize = 16;
constexpr std::uint32_t kScaleRegister = 0x1000, kOffsetRegister = 0x1008, kInvalidRegister = 0x1010, kUnitRegister = 0x1018;
constexpr std::size_t kTruthKept = 100000;  // profiles whose truth is held for the head to take

void write_be_double(ArvFakeCamera* cam, std::uint32_t address, double v) {
  std::uint64_t bits = std::bit_cast<std::uint64_t>(v);
  unsigned char be[8];
  for (int k = 0; k < 8; ++k) be[k] = static_cast<unsigned char>(bits >> (56 - 8 * k));
  arv_fake_camera_write_memory(cam, address, 8, be);
}

}  // namespace

struct SimGigeScanner::Impl {
  planner::SensorModel sensor;
  planner::OcclusionScene scene;
  std::function<Eigen::Isometry3d()> pose;
  SimGigeOptions options;
  std::string xml_path;
  ArvGvFakeCamera* gv = nullptr;
  ArvFakeCamera* cam = nullptr;

  struct Edge {
    std::uint64_t index;
    Eigen::Isometry3d pose;
  };
  struct Line {
    std::uint64_t index;
    std::vector<std::uint16_t> range;  // one count per ray
  };
  std::mutex mu;
  std::condition_variable cv;
  std::deque<Edge> pending;                      // triggered, not yet measured
  std::deque<Line> lines;                        // measured, not yet in a frame
  std::deque<std::vector<std::uint16_t>> frames;  // assembled, waiting for the emulator to send
  std::map<std::uint64_t, std::vector<planner::SampleTruth>> truth;  // per trigger counter, until taken
  std::chrono::steady_clock::time_point last_edge = std::chrono::steady_clock::now();
  int drop = 0;
  std::uint64_t sent = 0, next_index = 0;
  bool level = false, stop = false, acquiring = false;
  std::thread worker;

  Impl(planner::SensorModel s, const planner::TriangleMesh& m, std::function<Eigen::Isometry3d()> p, SimGigeOptions o)
      : sensor(std::move(s)), scene(m), pose(std::move(p)), options(std::move(o)) {}

  std::uint32_t reg(std::uint32_t address) {
    guint32 v = 0;
    arv_fake_camera_read_register(cam, address, &v);
    return v;
  }

  Line measure(const Edge& e, std::vector<planner::SampleTruth>& hit) {
    planner::SensorModel one = sensor;  // one profile: a vanishing sweep, the first of two rows (SimScanner)
    one.samples_y = 2;
    planner::ScanOptions o;
    o.seed = planner::mix_seed(options.seed, e.index);
    o.object_triangles = options.object_triangles;
    const planner::RangeImage img = planner::virtual_scan(scene, one, {e.pose, 1e-6}, o);
    Line l{e.index, std::vector<std::uint16_t>(static_cast<std::size_t>(img.columns), options.invalid_value)};
    hit.assign(static_cast<std::size_t>(img.columns), planner::SampleTruth{});
    if (!img.truth.empty()) std::copy_n(img.truth.begin(), img.columns, hit.begin());  // row 0
    for (int i = 0; i < img.columns; ++i) {
      const planner::RangeSample& s = img.at(i, 0);
      if (!s.valid()) continue;
      const double counts = std::round((-s.camera_mm.z() - options.offset_mm) / options.scale_mm);
      l.range[static_cast<std::size_t>(i)] = static_cast<std::uint16_t>(std::clamp(counts, 1.0, 65534.0));
    }
    return l;
  }

  /// Up to `height` lines into one frame, padded with all-ones marks: what the emulator sends next.
  std::vector<std::uint16_t> assemble(int width, int height) {
    const int cols = width - 2;
    std::vector<std::uint16_t> f(static_cast<std::size_t>(width) * height, options.invalid_value);
    for (int r = 0; r < height; ++r) {
      std::uint16_t* row = f.data() + static_cast<std::size_t>(r) * width;
      if (lines.empty()) {
        row[cols] = row[cols + 1] = 0xFFFF;
        continue;
      }
      const Line& l = lines.front();
      std::copy_n(l.range.begin(), std::min<std::size_t>(l.range.size(), static_cast<std::size_t>(cols)), row);
      row[cols] = static_cast<std::uint16_t>(l.index >> 16);
      row[cols + 1] = static_cast<std::uint16_t>(l.index & 0xFFFF);
      lines.pop_front();
    }
    return f;
  }

  void loop() {
    std::unique_lock<std::mutex> lock(mu);
    while (!stop) {
      cv.wait_for(lock, std::chrono::milliseconds(1), [&] { return stop || !pending.empty(); });
      if (reg(ARV_FAKE_CAMERA_REGISTER_ACQUISITION) == 0) acquiring = false;  // stopped: the next start restarts the counter
      while (!pending.empty()) {
        const Edge e = pending.front();
        pending.pop_front();
        lock.unlock();
        std::vector<planner::SampleTruth> hit;
        Line l = measure(e, hit);
        lock.lock();
        truth[l.index] = std::move(hit);
        while (truth.size() > kTruthKept) truth.erase(truth.begin());  // never taken (lost on the wire)
        lines.push_back(std::move(l));
      }
      const int width = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_WIDTH));
      const int height = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_HEIGHT));
      if (width < 3 || height < 1) continue;
      bool armed = false;
      while (static_cast<int>(lines.size()) >= height ||
             (!lines.empty() && std::chrono::steady_clock::now() - last_edge > options.flush_after)) {
        std::vector<std::uint16_t> f = assemble(width, height);
        if (drop > 0) {
          --drop;  // lost on the wire
          continue;
        }
        frames.push_back(std::move(f));
        armed = true;
      }
      // The emulator sends a frame when its trigger register is set (its "software" source is our Line0):
      // set here for a new frame, and by fill() while frames remain. Never otherwise: an extra set would
      // send a frame of padding lines.
      if (armed) arv_fake_camera_write_register(cam, ARV_FAKE_CAMERA_REGISTER_TRIGGER_SOFTWARE, 1);
    }
  }

  static void fill(ArvBuffer* buffer, void* self_ptr, guint32, guint32, ArvPixelFormat) {
    auto* self = static_cast<Impl*>(self_ptr);
    // arv_buffer_get_data's size is what was received so far (0 here); the emulator has checked that the
    // buffer holds the payload its Width x Height x 16 bits announce.
    auto* data = static_cast<unsigned char*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    const std::size_t size = static_cast<std::size_t>(arv_buffer_get_image_width(buffer)) * arv_buffer_get_image_height(buffer) * 2;
    std::lock_guard<std::mutex> lock(self->mu);
    if (self->frames.empty()) {
      std::memset(data, 0xFF, size);  // nothing due: every line padding
      return;
    }
    const std::vector<std::uint16_t>& f = self->frames.front();
    std::memcpy(data, f.data(), std::min(size, f.size() * 2));
    self->frames.pop_front();
    ++self->sent;
    if (!self->frames.empty()) arv_fake_camera_write_register(self->cam, ARV_FAKE_CAMERA_REGISTER_TRIGGER_SOFTWARE, 1);
  }
};

SimGigeScanner::SimGigeScanner(planner::SensorModel sensor, const planner::TriangleMesh& scene_mm,
                               std::function<Eigen::Isometry3d()> camera_pose, SimGigeOptions options)
    : impl_(std::make_unique<Impl>(std::move(sensor), scene_mm, std::move(camera_pose), options)), options_(std::move(options)) {
  Impl& d = *impl_;
  if (!(d.options.scale_mm > 0.0) || d.sensor.samples_x + 2 > 2048)
    throw DriverError(DriverError::Kind::refused, "sim scanner", "options", "scale_mm must be > 0 and samples_x + 2 <= 2048");
  // The emulator reads its GenICam description from a file: ours, written once per instance.
  char path[] = "/tmp/scancell-gige-XXXXXX";
  const int fd = mkstemp(path);
  if (fd < 0) throw DriverError(DriverError::Kind::connection, "sim scanner", "GenICam XML", "cannot create a temporary file");
  close(fd);
  d.xml_path = path;
  std::string xml = kScancellLineScannerXml;
  if (!d.options.offer_coord3d) {
    // A Mono16-only device: its PixelFormat enumeration has no Coord3D_C16 entry.
    const auto at = xml.find("<EnumEntry Name=\"Coord3D_C16\"");
    if (at != std::string::npos) xml.erase(at, xml.find("</EnumEntry>", at) + 12 - at);
  }
  if (d.options.user_id.size() > 15 || d.options.serial.empty() || d.options.serial.size() > 15) {
    std::remove(d.xml_path.c_str());
    throw DriverError(DriverError::Kind::refused, "sim scanner", "options", "serial (1 to 15 characters) or user_id (up to 15) too long");
  }
  std::ofstream(d.xml_path) << xml;
  d.gv = arv_gv_fake_camera_new_full(d.options.interface.c_str(), d.options.serial.c_str(), d.xml_path.c_str());
  if (!d.gv || !arv_gv_fake_camera_is_running(d.gv)) {
    if (d.gv) g_object_unref(d.gv);
    std::remove(d.xml_path.c_str());
    throw DriverError(DriverError::Kind::connection, "sim scanner", d.options.interface + ":3956",
                      "the GigE Vision emulator cannot listen there (another device on that address?)");
  }
  d.cam = arv_gv_fake_camera_get_fake_camera(d.gv);
  write_be_double(d.cam, kScaleRegister, d.options.scale_mm);
  write_be_double(d.cam, kOffsetRegister, d.options.offset_mm);
  write_be_double(d.cam, kInvalidRegister, d.options.invalid_value);
  arv_fake_camera_write_register(d.cam, kUnitRegister, 0);  // Millimeter
  arv_fake_camera_write_register(d.cam, ARV_FAKE_CAMERA_REGISTER_WIDTH, static_cast<guint32>(d.sensor.samples_x + 2));
  arv_fake_camera_write_register(d.cam, ARV_FAKE_CAMERA_REGISTER_HEIGHT, 16);
  arv_fake_camera_write_register(d.cam, ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT,
                                 d.options.offer_coord3d ? 0x011000B8u /* Coord3D_C16 (PFNC) */ : 0x01100007u /* Mono16 */);
  if (!d.options.user_id.empty()) {
    // The user-defined name of the bootstrap registers: discovery answers with it, so a driver can open by it.
    char name[kUserNameSize] = {};
    std::memcpy(name, d.options.user_id.data(), d.options.user_id.size());
    arv_fake_camera_write_memory(d.cam, kUserNameRegister, sizeof name, name);
  }
  arv_fake_camera_set_trigger_frequency(d.cam, d.options.line_rate_hz);
  arv_fake_camera_set_fill_pattern(d.cam, &Impl::fill, impl_.get());
  d.worker = std::thread([this] { impl_->loop(); });
}

SimGigeScanner::~SimGigeScanner() {
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    impl_->stop = true;
  }
  impl_->cv.notify_all();
  impl_->worker.join();
  g_object_unref(impl_->gv);  // stops the emulator's threads before the fill callback's data goes
  std::remove(impl_->xml_path.c_str());
}

void SimGigeScanner::set(bool level) {
  const bool rising = level && !impl_->level;
  impl_->level = level;
  if (!rising) return;
  const Eigen::Isometry3d p = impl_->pose();
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    // Like a real scanner: no acquisition, no profile; the trigger counter restarts with each acquisition
    // (a driver opened afresh counts from 0), and what an earlier one left unsent is gone.
    if (impl_->reg(ARV_FAKE_CAMERA_REGISTER_ACQUISITION) == 0) {
      impl_->acquiring = false;
      return;
    }
    if (!impl_->acquiring) {
      impl_->acquiring = true;
      impl_->next_index = 0;
      impl_->pending.clear();
      impl_->lines.clear();
      impl_->frames.clear();
      impl_->truth.clear();
    }
    impl_->pending.push_back({impl_->next_index++, p});
    impl_->last_edge = std::chrono::steady_clock::now();
  }
  impl_->cv.notify_all();
}

void SimGigeScanner::drop_next_frames(int n) {
  std::lock_guard<std::mutex> lock(impl_->mu);
  impl_->drop += n;
}

std::vector<planner::SampleTruth> SimGigeScanner::take_truth(std::uint64_t index) {
  std::lock_guard<std::mutex> lock(impl_->mu);
  auto it = impl_->truth.find(index);
  if (it == impl_->truth.end()) return {};
  std::vector<planner::SampleTruth> t = std::move(it->second);
  impl_->truth.erase(it);
  return t;
}

std::uint64_t SimGigeScanner::frames_sent() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->sent;
}

}  // namespace scancell::drivers
