#pragma once
// A GenICam / GigE Vision laser line-profile scanner through Aravis (SICK Ranger3/Ruler, AT C5/C6 and the
// like follow the SFNC Scan3dControl features). One image line is one profile: Width = rays across the fan
// (+ mark columns), Height = profiles per frame, PixelFormat Coord3D_C16 = range counts that
// Scan3dCoordinateScale/Offset turn into mm. Each profile is triggered by the hardware line the cell's
// trigger output drives (TriggerSource), and arrives in trigger order; a lost or incomplete frame becomes
// profiles marked lost, never a silent shift of the rows after it.
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include "drivers/axis.hpp"
#include "drivers/scanner.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::drivers {

struct GenicamConfig {
  /// Each setting's range, declared here once: the daemon's config loader and check_genicam_config use them.
  template <class T>
  struct Limits {
    T lo, hi;
  };
  std::string device;                   // Aravis device id: IP address, serial number or user id
  int profiles_per_frame = 16;          // Height
  std::string trigger_line = "Line0";   // TriggerSource for FrameStart (the line the trigger output drives)
  int packet_size_bytes = 0;            // GevSCPSPacketSize; 0: keep the device's
  int mark_columns = 2;                 // 0 or 2: last columns of each line carry the 32-bit trigger counter
  double mono16_scale_mm = 0.0;         // Mono16 fallback only: mm per count (a Coord3D device states its own)
  double mono16_offset_mm = 0.0;
  double exposure_us = 0.0;             // ExposureTime; 0: keep the device's
  int stream_buffers = 32;              // buffers queued on the stream
  static constexpr Limits<int> profiles_per_frame_limits{1, 2048}, packet_size_bytes_limits{576, 9000},
      stream_buffers_limits{2, 1024};
  static constexpr Limits<double> mono16_scale_mm_limits{0.0, 1.0}, mono16_offset_mm_limits{-10000.0, 10000.0},
      exposure_us_limits{0.0, 1e6};
};

/// Refuses a configuration before any device is touched (DriverError refused, naming the key).
void check_genicam_config(const GenicamConfig& config, const std::string& key_path = "scanner");

/// What the device stated when it was opened (its features, after configuration).
struct GenicamDeviceInfo {
  std::string vendor, model, pixel_format;
  std::string id;  // what the device was opened by: scanner.device, or the Aravis id a bare serial number resolved to
  int width = 0, height = 0;
  int packet_size_bytes = 0;  // GevSCPSPacketSize as the device reads it back (0: not a GigE Vision device)
  double scale_mm = 0.0, offset_mm = 0.0, invalid_value = 0.0;
  bool has_invalid_value = false;
};

class GenicamScanner : public Scanner {
 public:
  /// Opens the device, validates and sets its features, queues buffers and starts the acquisition: from
  /// here every pulse on the trigger line yields one profile. DriverError (connection, protocol, refused)
  /// naming the feature otherwise.
  GenicamScanner(planner::SensorModel sensor, GenicamConfig config);
  ~GenicamScanner() override;
  GenicamScanner(const GenicamScanner&) = delete;
  GenicamScanner& operator=(const GenicamScanner&) = delete;

  /// The next profile in trigger order. A profile the device never delivered (lost or incomplete frame)
  /// comes back with `lost` set and no samples, at its place in the order.
  Profile acquire(std::chrono::milliseconds timeout) override;

  struct Counters {
    std::uint64_t frames = 0, incomplete_frames = 0, lost_profiles = 0, padding_lines = 0;
  };
  Counters counters() const { return counters_; }
  const GenicamDeviceInfo& device() const { return info_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  planner::SensorModel sensor_;
  GenicamConfig config_;
  GenicamDeviceInfo info_;
  Counters counters_;
  std::deque<Profile> ready_;
  std::uint64_t next_index_ = 0;   // the trigger counter the next profile should carry
  std::uint64_t next_frame_ = 0;   // the frame id expected next (marks off: order from frame ids)
  bool first_frame_ = true;
  void decode(const std::uint16_t* data, int width, int height, std::uint64_t frame_id);
  Profile profile_of(const std::uint16_t* line, std::uint64_t index) const;
  void push_lost(std::uint64_t upto);
};

}  // namespace scancell::drivers
