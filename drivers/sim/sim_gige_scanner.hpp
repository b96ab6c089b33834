#pragma once
// A simulated GigE Vision line-profile scanner on the real wire: Aravis' ArvGvFakeCamera (a GigE Vision
// device emulator: GVCP control, GVSP stream) on a local interface, described by our GenICam XML
// (drivers/genicam/scancell-line-scanner.xml: SFNC Scan3d features, Coord3D_C16, TriggerSource Line0).
// Its trigger input is a DigitalOutput, so the cell's trigger drives it like the Line0 input of a real
// scanner: each rising edge captures one profile with the virtual scanner at the pose the simulated axes
// report, and every `Height` profiles (or after `flush_after` without a new edge) go out as one frame.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>

#include "drivers/gpio.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::drivers {

struct SimGigeOptions {
  std::string interface = "127.0.0.1";   // an interface address or name (GVCP port 3956; one device each)
  std::string serial = "SIM0001";        // a driver opens it by this, by "Aravis-<serial>", the user id or the address
  std::string user_id;                   // GigE Vision user-defined name (up to 15 characters); empty: none
  bool offer_coord3d = true;             // false: PixelFormat offers Mono16 only (the driver needs a configured scale)
  double scale_mm = 0.01;                // Scan3dCoordinateScale: mm per range count (reach 655 mm)
  double offset_mm = 0.0;                // Scan3dCoordinateOffset
  std::uint16_t invalid_value = 0;       // Scan3dInvalidDataValue: no return
  double line_rate_hz = 4000.0;          // how often the emulator looks for a frame to send
  std::chrono::milliseconds flush_after{20};  // a short frame goes out when no edge came for this long
  std::uint64_t seed = 1;
  std::size_t object_triangles = 0;      // scene triangles from here on are fixtures (block, give no sample)
};

class SimGigeScanner : public DigitalOutput {
 public:
  SimGigeScanner(planner::SensorModel sensor, const planner::TriangleMesh& scene_mm,
                 std::function<Eigen::Isometry3d()> camera_pose, SimGigeOptions options = {});
  ~SimGigeScanner() override;
  SimGigeScanner(const SimGigeScanner&) = delete;
  SimGigeScanner& operator=(const SimGigeScanner&) = delete;
  void set(bool level) override;  // the Line0 input
  /// The next `n` frames are dropped on the wire (a lost frame; the driver must count their profiles).
  void drop_next_frames(int n);
  /// The id a GenicamConfig::device can name (the emulator answers discovery as vendor "Aravis").
  std::string address() const { return options_.interface; }
  std::uint64_t frames_sent() const;
  /// Simulation side data, beside the wire (GigE Vision carries ranges only): what the virtual scanner knew
  /// of the profile sent with trigger counter `index` (the true hit and its triangle per column), taken once;
  /// empty when unknown. The daemon's simulated head joins it to the driver's profiles so that a job on the
  /// GigE path gets the same ground-truth checks as one on the in-process SimScanner; nothing on a real
  /// scanner's path reads it.
  std::vector<planner::SampleTruth> take_truth(std::uint64_t index);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  SimGigeOptions options_;
};

}  // namespace scancell::drivers
