#include "drivers/genicam/genicam_scanner.hpp"

#include <arv.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

namespace scancell::drivers {

namespace {

constexpr const char* kDev = "scanner";
constexpr std::uint32_t kPaddingMark = 0xFFFFFFFFu;

DriverError refused(const std::string& where, const std::string& why) {
  return DriverError(DriverError::Kind::refused, kDev, where, why);
}

/// A number as the config would write it: 2048, 0.5, 1e+06.
std::string fmt_number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

/// A GError from Aravis as a DriverError naming the feature, freed here.
[[noreturn]] void throw_gerror(GError* e, DriverError::Kind kind, const std::string& where, const std::string& hint = {}) {
  const std::string msg = e && e->message ? e->message : "unknown Aravis error";
  if (e) g_error_free(e);
  throw DriverError(kind, kDev, where, msg + hint);
}

/// Aravis opens a device by its address, MAC, user-defined name or "vendor-serial" / "vendor-model-serial";
/// a bare serial number (what is printed on the scanner) is looked up among the discovered devices here.
/// Returns the Aravis id of the one device with that serial number, or empty when none has it.
std::string serial_to_device_id(const std::string& serial) {
  arv_update_device_list();
  std::vector<std::string> found;
  for (unsigned i = 0; i < arv_get_n_devices(); ++i) {
    const char* id = arv_get_device_id(i);
    const char* sn = arv_get_device_serial_nbr(i);
    if (id && sn && serial == sn) found.emplace_back(id);
  }
  if (found.size() > 1)
    throw refused("opening '" + serial + "'", std::to_string(found.size()) + " devices have this serial number (" + found[0] + ", " +
                                                 found[1] + "): name one by address in scanner.device");
  return found.empty() ? std::string() : found[0];
}

}  // namespace

void check_genicam_config(const GenicamConfig& c, const std::string& key) {
  if (c.device.empty()) throw refused(key + ".device", "empty: give the scanner's IP address, serial number or user id");
  using G = GenicamConfig;
  auto outside = [](auto v, auto lim) { return !(v >= lim.lo && v <= lim.hi); };
  auto range = [](auto lim) { return "[" + fmt_number(lim.lo) + ", " + fmt_number(lim.hi) + "]"; };
  if (outside(c.profiles_per_frame, G::profiles_per_frame_limits))
    throw refused(key + ".profiles_per_frame", std::to_string(c.profiles_per_frame) + " outside " + range(G::profiles_per_frame_limits));
  if (c.trigger_line.empty()) throw refused(key + ".trigger_line", "empty: name the TriggerSource line, e.g. Line0");
  if (c.packet_size_bytes != 0 && outside(c.packet_size_bytes, G::packet_size_bytes_limits))
    throw refused(key + ".packet_size_bytes",
                  std::to_string(c.packet_size_bytes) + " outside " + range(G::packet_size_bytes_limits) + " (0 keeps the device's)");
  if (c.mark_columns != 0 && c.mark_columns != 2)
    throw refused(key + ".mark_columns", std::to_string(c.mark_columns) + ": 2 (trigger counter in each line) or 0");
  if (c.mark_columns == 0 && c.profiles_per_frame != 1)
    throw refused(key + ".mark_columns", "0 needs profiles_per_frame 1: without a counter in each line a short frame cannot be told apart");
  if (outside(c.mono16_scale_mm, G::mono16_scale_mm_limits))
    throw refused(key + ".mono16_scale_mm", fmt_number(c.mono16_scale_mm) + " outside " + range(G::mono16_scale_mm_limits));
  if (outside(c.mono16_offset_mm, G::mono16_offset_mm_limits))
    throw refused(key + ".mono16_offset_mm", fmt_number(c.mono16_offset_mm) + " outside " + range(G::mono16_offset_mm_limits));
  if (outside(c.exposure_us, G::exposure_us_limits))
    throw refused(key + ".exposure_us", fmt_number(c.exposure_us) + " outside " + range(G::exposure_us_limits));
  if (outside(c.stream_buffers, G::stream_buffers_limits))
    throw refused(key + ".stream_buffers", std::to_string(c.stream_buffers) + " outside " + range(G::stream_buffers_limits));
}

struct GenicamScanner::Impl {
  ArvCamera* camera = nullptr;
  ArvDevice* device = nullptr;  // owned by camera
  ArvStream* stream = nullptr;
  std::atomic<bool> control_lost{false};
  gulong lost_handler = 0;
  static void on_control_lost(ArvDevice*, gpointer self) { static_cast<Impl*>(self)->control_lost = true; }
  ~Impl() {
    // A device that is gone is not told to stop: every GVCP retry would wait out its timeout.
    if (camera && !control_lost) arv_camera_stop_acquisition(camera, nullptr);
    if (device && lost_handler) g_signal_handler_disconnect(device, lost_handler);
    if (stream) g_object_unref(stream);
    if (camera) g_object_unref(camera);
  }
  bool has(const char* feature) { return arv_device_is_feature_available(device, feature, nullptr); }
  std::int64_t get_int(const char* f) {
    GError* e = nullptr;
    const std::int64_t v = arv_device_get_integer_feature_value(device, f, &e);
    if (e) throw_gerror(e, DriverError::Kind::protocol, std::string("reading ") + f);
    return v;
  }
  double get_float(const char* f) {
    GError* e = nullptr;
    const double v = arv_device_get_float_feature_value(device, f, &e);
    if (e) throw_gerror(e, DriverError::Kind::protocol, std::string("reading ") + f);
    return v;
  }
  std::string get_string(const char* f) {
    GError* e = nullptr;
    const char* v = arv_device_get_string_feature_value(device, f, &e);
    if (e) throw_gerror(e, DriverError::Kind::protocol, std::string("reading ") + f);
    return v ? v : "";
  }
  void set_int(const char* f, std::int64_t v, const std::string& key) {
    GError* e = nullptr;
    std::int64_t lo = 0, hi = 0;
    arv_device_get_integer_feature_bounds(device, f, &lo, &hi, &e);
    if (e) throw_gerror(e, DriverError::Kind::protocol, std::string("reading the range of ") + f);
    if (v < lo || v > hi)
      throw refused(std::string("setting ") + f + " to " + std::to_string(v),
                    "the device allows [" + std::to_string(lo) + ", " + std::to_string(hi) + "] (check " + key + ")");
    arv_device_set_integer_feature_value(device, f, v, &e);
    if (e) throw_gerror(e, DriverError::Kind::refused, std::string("setting ") + f + " to " + std::to_string(v), " (check " + key + ")");
    if (get_int(f) != v)
      throw refused(std::string("setting ") + f + " to " + std::to_string(v), "the device reads back " + std::to_string(get_int(f)) + " (check " + key + ")");
  }
  void set_enum(const char* f, const std::string& v, const std::string& key) {
    GError* e = nullptr;
    arv_device_set_string_feature_value(device, f, v.c_str(), &e);
    if (e) throw_gerror(e, DriverError::Kind::refused, std::string("setting ") + f + " to " + v, " (check " + key + ")");
  }
};

GenicamScanner::GenicamScanner(planner::SensorModel sensor, GenicamConfig config)
    : impl_(std::make_unique<Impl>()), sensor_(std::move(sensor)), config_(std::move(config)) {
  check_genicam_config(config_);
  if (sensor_.kind != planner::SensorKind::line_scan) throw refused("sensor model", "a GenICam line-profile scanner needs a line_scan sensor model");
  GError* e = nullptr;
  info_.id = config_.device;
  impl_->camera = arv_camera_new(info_.id.c_str(), &e);
  if (!impl_->camera) {
    // Not an id Aravis knows: a bare serial number is looked up (one more discovery, only on this path).
    const std::string by_serial = serial_to_device_id(config_.device);
    if (!by_serial.empty()) {
      g_clear_error(&e);
      info_.id = by_serial;
      impl_->camera = arv_camera_new(info_.id.c_str(), &e);
    }
  }
  if (!impl_->camera)
    throw_gerror(e, DriverError::Kind::connection, "opening '" + config_.device + "'",
                 " (check scanner.device, the network route to the scanner, and that no other program holds it)");
  impl_->device = arv_camera_get_device(impl_->camera);
  impl_->lost_handler = g_signal_connect(impl_->device, "control-lost", G_CALLBACK(&Impl::on_control_lost), impl_.get());
  Impl& d = *impl_;
  info_.vendor = d.has("DeviceVendorName") ? d.get_string("DeviceVendorName") : "";
  info_.model = d.has("DeviceModelName") ? d.get_string("DeviceModelName") : "";

  // Image geometry: one line per profile, one column per ray (+ the counter marks).
  const int width = sensor_.samples_x + config_.mark_columns;
  d.set_int("Width", width, "sensor.samples_x and scanner.mark_columns");
  d.set_int("Height", config_.profiles_per_frame, "scanner.profiles_per_frame");
  info_.width = width;
  info_.height = config_.profiles_per_frame;

  // Range data: Coord3D_C16 states its own scale; Mono16 only with a configured one.
  GError* pe = nullptr;
  arv_device_set_string_feature_value(d.device, "PixelFormat", "Coord3D_C16", &pe);
  if (pe) {
    g_error_free(pe);
    if (config_.mono16_scale_mm <= 0.0)
      throw refused("PixelFormat", "the device offers no Coord3D_C16; Mono16 range data needs scanner.mono16_scale_mm > 0");
    d.set_enum("PixelFormat", "Mono16", "scanner.mono16_scale_mm");
  }
  info_.pixel_format = d.get_string("PixelFormat");
  if (info_.pixel_format == "Coord3D_C16") {
    for (const char* f : {"Scan3dCoordinateScale", "Scan3dCoordinateOffset"})
      if (!d.has(f)) throw refused(f, "missing: a Coord3D_C16 device must state it (SFNC Scan3dControl)");
    if (d.has("Scan3dDistanceUnit") && d.get_string("Scan3dDistanceUnit") != "Millimeter")
      throw refused("Scan3dDistanceUnit", "'" + d.get_string("Scan3dDistanceUnit") + "': set the device to Millimeter");
    info_.scale_mm = d.get_float("Scan3dCoordinateScale");
    info_.offset_mm = d.get_float("Scan3dCoordinateOffset");
    if (d.has("Scan3dInvalidDataValue")) {
      info_.invalid_value = d.get_float("Scan3dInvalidDataValue");
      info_.has_invalid_value = true;
    }
  } else if (info_.pixel_format == "Mono16") {
    info_.scale_mm = config_.mono16_scale_mm;
    info_.offset_mm = config_.mono16_offset_mm;
    info_.invalid_value = 0.0;  // a Mono16 range of 0 counts is no return
    info_.has_invalid_value = true;
  } else {
    throw refused("PixelFormat", "'" + info_.pixel_format + "': range data must be Coord3D_C16 or Mono16");
  }
  if (!(std::isfinite(info_.scale_mm) && info_.scale_mm > 0.0 && info_.scale_mm < 1.0) || !std::isfinite(info_.offset_mm))
    throw refused("Scan3dCoordinateScale", "scale " + std::to_string(info_.scale_mm) + " mm/count, offset " +
                                                std::to_string(info_.offset_mm) + " mm: the scale must be in (0, 1) mm and both finite");
  const double reach_mm = info_.offset_mm + info_.scale_mm * 65534.0;
  if (reach_mm < sensor_.range_max_mm)
    throw refused("Scan3dCoordinateScale", "16-bit range reaches " + std::to_string(reach_mm) + " mm, the sensor model's R_max is " +
                                                std::to_string(sensor_.range_max_mm) + " mm");

  // Triggering: every frame line is a pulse on the configured line.
  d.set_enum("TriggerSelector", "FrameStart", "scanner.trigger_line");
  d.set_enum("TriggerMode", "On", "scanner.trigger_line");
  d.set_enum("TriggerSource", config_.trigger_line, "scanner.trigger_line");
  if (d.has("TriggerActivation")) d.set_enum("TriggerActivation", "RisingEdge", "scanner.trigger_line");
  if (config_.exposure_us > 0.0) {
    GError* xe = nullptr;
    arv_device_set_float_feature_value(d.device, "ExposureTime", config_.exposure_us, &xe);
    if (xe) throw_gerror(xe, DriverError::Kind::refused, "setting ExposureTime", " (check scanner.exposure_us)");
  }
  if (config_.packet_size_bytes > 0) d.set_int("GevSCPSPacketSize", config_.packet_size_bytes, "scanner.packet_size_bytes");
  if (d.has("GevSCPSPacketSize")) info_.packet_size_bytes = static_cast<int>(d.get_int("GevSCPSPacketSize"));
  if (d.has("AcquisitionMode")) d.set_enum("AcquisitionMode", "Continuous", "scanner");

  d.stream = arv_camera_create_stream(d.camera, nullptr, nullptr, &e);
  if (!d.stream) throw_gerror(e, DriverError::Kind::connection, "creating the stream", " (check the route back from the scanner)");
  const std::int64_t payload = d.get_int("PayloadSize");
  if (payload != static_cast<std::int64_t>(width) * config_.profiles_per_frame * 2)
    throw refused("PayloadSize", std::to_string(payload) + " bytes for " + std::to_string(width) + " x " +
                                     std::to_string(config_.profiles_per_frame) + " 16-bit pixels");
  for (int b = 0; b < config_.stream_buffers; ++b) arv_stream_push_buffer(d.stream, arv_buffer_new(static_cast<std::size_t>(payload), nullptr));
  arv_camera_start_acquisition(d.camera, &e);
  if (e) throw_gerror(e, DriverError::Kind::protocol, "AcquisitionStart");
}

GenicamScanner::~GenicamScanner() = default;

Profile GenicamScanner::profile_of(const std::uint16_t* line, std::uint64_t index) const {
  Profile p;
  p.index = index;
  p.time = std::chrono::steady_clock::now();
  p.samples.resize(static_cast<std::size_t>(sensor_.samples_x));
  for (int i = 0; i < sensor_.samples_x; ++i) {
    const std::uint16_t v = line[i];
    if (info_.has_invalid_value && static_cast<double>(v) == info_.invalid_value) continue;
    const double z = v * info_.scale_mm + info_.offset_mm;  // range along the boresight
    if (!(z > 0.0)) continue;
    planner::RangeSample& s = p.samples[static_cast<std::size_t>(i)];
    // Camera frame (planner/core/sensor.hpp): laser at the origin, boresight -z, ray i across the fan in x.
    s.camera_mm = Eigen::Vector3f(static_cast<float>(planner::ray_tan_x(sensor_, i) * z), 0.0f, static_cast<float>(-z));
    // Eq. 3.4 at normal incidence across the sweep: one profile cannot tell θyz; σz grows as 1/cos θyz.
    s.sigma_z_mm = static_cast<float>(sensor_.noise_cz_per_mm * z * z);
    s.measured = true;
  }
  return p;
}

void GenicamScanner::push_lost(std::uint64_t upto) {
  for (; next_index_ < upto; ++next_index_) {
    Profile p;
    p.index = next_index_;
    p.lost = true;
    p.time = std::chrono::steady_clock::now();
    ready_.push_back(std::move(p));
    ++counters_.lost_profiles;
  }
}

void GenicamScanner::decode(const std::uint16_t* data, int width, int height, std::uint64_t frame_id) {
  const int cols = width - config_.mark_columns;
  if (config_.mark_columns == 0) {
    // One profile per frame: its index follows the frame ids (GigE Vision 1.x block ids wrap 65535 -> 1).
    if (!first_frame_) {
      std::uint64_t gap = frame_id >= next_frame_ ? frame_id - next_frame_ : frame_id + 65535 - next_frame_;
      push_lost(next_index_ + gap);
    }
    first_frame_ = false;
    next_frame_ = frame_id >= 65535 ? 1 : frame_id + 1;
    ready_.push_back(profile_of(data, next_index_++));
    return;
  }
  for (int r = 0; r < height; ++r) {
    const std::uint16_t* line = data + static_cast<std::size_t>(r) * width;
    const std::uint32_t mark = (static_cast<std::uint32_t>(line[cols]) << 16) | line[cols + 1];
    if (mark == kPaddingMark) {
      ++counters_.padding_lines;
      continue;
    }
    if (mark < next_index_)
      throw DriverError(DriverError::Kind::protocol, kDev, "frame " + std::to_string(frame_id) + " line " + std::to_string(r),
                        "trigger counter " + std::to_string(mark) + " after " + std::to_string(next_index_ - 1) +
                            " (out of order, or the scanner restarted its counter)");
    push_lost(mark);  // profiles of frames that never came
    ready_.push_back(profile_of(line, next_index_++));
  }
}

Profile GenicamScanner::acquire(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (ready_.empty()) {
    if (impl_->control_lost)
      throw DriverError(DriverError::Kind::connection, kDev, "acquire", "the scanner stopped answering (control lost; check its power and cable)");
    const auto left = std::chrono::duration_cast<std::chrono::microseconds>(deadline - std::chrono::steady_clock::now());
    ArvBuffer* b = left.count() > 0 ? arv_stream_timeout_pop_buffer(impl_->stream, static_cast<guint64>(left.count())) : nullptr;
    if (!b)
      throw DriverError(DriverError::Kind::timeout, kDev, "acquire",
                        "no profile within " + std::to_string(timeout.count()) + " ms (is the trigger line " + config_.trigger_line + " wired and pulsing?)");
    ++counters_.frames;
    if (arv_buffer_get_status(b) != ARV_BUFFER_STATUS_SUCCESS) {
      // Its lines are unknown: the next complete frame's counters say how many profiles it held.
      ++counters_.incomplete_frames;
    } else {
      std::size_t size = 0;
      const void* data = arv_buffer_get_data(b, &size);
      const int w = static_cast<int>(arv_buffer_get_image_width(b)), h = static_cast<int>(arv_buffer_get_image_height(b));
      if (w != info_.width || h != info_.height || size < static_cast<std::size_t>(w) * h * 2) {
        const std::uint64_t id = arv_buffer_get_frame_id(b);
        arv_stream_push_buffer(impl_->stream, b);
        throw DriverError(DriverError::Kind::protocol, kDev, "frame " + std::to_string(id),
                          std::to_string(w) + " x " + std::to_string(h) + " pixels, configured " + std::to_string(info_.width) +
                              " x " + std::to_string(info_.height));
      }
      // Copy out before the buffer goes back to the stream (alignment of the payload is not guaranteed).
      std::vector<std::uint16_t> px(static_cast<std::size_t>(w) * h);
      std::memcpy(px.data(), data, px.size() * 2);
      const std::uint64_t id = arv_buffer_get_frame_id(b);
      arv_stream_push_buffer(impl_->stream, b);
      decode(px.data(), w, h, id);
      continue;
    }
    arv_stream_push_buffer(impl_->stream, b);
  }
  Profile p = std::move(ready_.front());
  ready_.pop_front();
  return p;
}

}  // namespace scancell::drivers
