// `scancell-sim scanner --gige ADDRESS --mesh FILE --cell FILE --sensor FILE --drivers FILE [--fit-mm N]
// [--serial S] [--seed N]`: a simulated GigE Vision line scanner as its own process (issue 18), the way a
// real one stands beside the drives. Aravis' ArvGvFakeCamera serves scancell's GenICam XML on ADDRESS; its
// Line0 is wired to the sweep drive's position-compare output (scanner.trigger_source: drive_compare). That
// wire is the drive's compare registers, read over Modbus TCP as a second client of the simulated drives:
// each pulse the drive counts triggers a profile of the virtual scanner at that pulse's compare position,
// with the other axes where the drives report them. The object rests on the plate as a job places a mesh
// given as it is (placement as_given). The daemon reads it with scanner.driver genicam, as a real scanner.
#include "tools/sim_scanner.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "drivers/config.hpp"
#include "drivers/modbus_axis.hpp"
#include "drivers/sim/sim_gige_scanner.hpp"
#include "planner/config.hpp"
#include "planner/geometry/mesh.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/kinematics/resting_poses.hpp"

namespace scancell::tools {
namespace {

namespace dr = scancell::drivers;
namespace sp = scancell::planner;

struct Options {
  std::string gige, mesh, cell, sensor, drivers, serial = "SIM0001";
  double fit_mm = 0.0;
  std::uint64_t seed = 1;
};

int usage() {
  std::cerr << "usage: scancell-sim scanner --gige ADDRESS --mesh FILE --cell FILE --sensor FILE --drivers FILE "
               "[--fit-mm N] [--serial S] [--seed N]\n";
  return 2;
}

/// The options, or nothing after saying what is missing.
std::optional<Options> parse(int argc, char** argv) {
  Options o;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::cerr << "scancell-sim scanner: " << a << " needs a value\n";
      return std::nullopt;
    }
    const std::string v = argv[++i];
    if (a == "--gige") o.gige = v;
    else if (a == "--mesh") o.mesh = v;
    else if (a == "--cell") o.cell = v;
    else if (a == "--sensor") o.sensor = v;
    else if (a == "--drivers") o.drivers = v;
    else if (a == "--serial") o.serial = v;
    else if (a == "--fit-mm") o.fit_mm = std::strtod(v.c_str(), nullptr);
    else if (a == "--seed") o.seed = std::strtoull(v.c_str(), nullptr, 10);
    else {
      std::cerr << "scancell-sim scanner: unknown option '" << a << "'\n";
      return std::nullopt;
    }
  }
  for (const auto& [name, value] : {std::pair{"--gige", &o.gige}, {"--mesh", &o.mesh}, {"--cell", &o.cell}, {"--sensor", &o.sensor},
                                    {"--drivers", &o.drivers}})
    if (value->empty()) {
      std::cerr << "scancell-sim scanner: " << name << " is required\n";
      return std::nullopt;
    }
  return o;
}

/// One Modbus client per cell axis, in the cell's axis order, from the drivers file (Modbus TCP only: the
/// compare counter is read over it).
std::vector<std::unique_ptr<dr::ModbusAxis>> connect_axes(const sp::CellModel& cell, const dr::DriverSetup& setup, const std::string& file) {
  std::vector<std::unique_ptr<dr::ModbusAxis>> axes;
  for (const auto& a : cell.axes) {
    const auto it = setup.axes.find(a.name);
    const auto* m = it == setup.axes.end() ? nullptr : std::get_if<dr::ModbusConfig>(&it->second);
    if (!m || m->host.empty())
      throw std::runtime_error(file + ": axes." + a.name + ": the simulated scanner reads the drives over Modbus TCP; this axis is not on it");
    dr::ModbusConfig c = *m;
    c.name = a.name;
    axes.push_back(std::make_unique<dr::ModbusAxis>(c));
  }
  return axes;
}

}  // namespace

int serve_scanner(int argc, char** argv, const volatile std::sig_atomic_t& stop) {
  const auto parsed = parse(argc, argv);
  if (!parsed) return usage();
  const Options& o = *parsed;
  try {
    sp::TriangleMesh mesh = sp::load_mesh(o.mesh);
    if (o.fit_mm > 0.0) sp::apply_scale(mesh, sp::fit_scale(mesh, o.fit_mm));
    const sp::CellModel cell = sp::load_cell(o.cell);
    const sp::SensorModel sensor = sp::load_sensor(o.sensor);
    sp::CellModel placed = cell;
    placed.object_on_table = sp::place_on_plate(mesh, cell.object_on_table.linear(), cell.object_on_table.translation());
    auto axes = connect_axes(cell, dr::load_driver_setup(o.drivers), o.drivers);
    const std::size_t sweep = cell.axis_index("sweep");
    std::mutex mu;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    dr::SimGigeOptions go;
    go.interface = o.gige;
    go.serial = o.serial;
    go.seed = o.seed;
    go.object_triangles = mesh.triangles.size();
    dr::SimGigeScanner device(sensor, sp::with_fixtures(mesh, placed), [&] {
      std::lock_guard<std::mutex> lock(mu);
      return pose;
    }, go);
    const Eigen::Vector3d at = placed.object_on_table.translation();
    std::cout << "scancell-sim: GigE Vision scanner " << o.serial << " on " << device.address()
              << ", Line0 wired to the sweep drive's position compare; the object on the plate at " << at.x() << ' ' << at.y() << ' '
              << at.z() << " mm" << std::endl;
    // The wire: every pulse the drive counts is one trigger, at its compare position. Polling can see a
    // re-arming before the last pulses of the arming before it: the drive's total count says how many there
    // were, and they are sent with the old arming's positions first.
    dr::ModbusAxis::CompareState last = axes[sweep]->position_compare();
    std::uint64_t profiles = 0;
    auto pulse = [&](const dr::ModbusAxis::CompareState& arm, int k, sp::JointVector& q) {
      q[sweep] = arm.start + k * arm.pitch;
      {
        std::lock_guard<std::mutex> lock(mu);
        pose = sp::forward_kinematics(placed, q);
      }
      device.set(true);
      device.set(false);
      ++profiles;
    };
    while (!stop) {
      const dr::ModbusAxis::CompareState c = axes[sweep]->position_compare();
      const auto news = static_cast<int>(c.total - last.total);
      if (news > 0) {
        sp::JointVector q(axes.size());
        for (std::size_t a = 0; a < axes.size(); ++a) q[a] = a == sweep ? 0.0 : axes[a]->state().position;
        const bool rearmed = c.start != last.start || c.pitch != last.pitch || c.fired - last.fired != news;
        const int of_old = rearmed ? std::max(0, news - c.fired) : news;
        for (int k = 0; k < of_old; ++k) pulse(last, last.fired + k, q);
        if (rearmed)
          for (int k = 0; k < c.fired; ++k) pulse(c, k, q);
      }
      last = c;
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    std::cout << "scancell-sim: " << profiles << " profiles, " << device.frames_sent() << " frames sent" << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "scancell-sim scanner: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace scancell::tools
