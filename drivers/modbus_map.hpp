#pragma once
// The scancell Modbus axis register map (docs/modbus-register-map.md), shared by the driver and the simulator.
#include <cstdint>

namespace scancell::drivers::modbus_map {

// Holding registers (function codes 3 read, 6/16 write), addresses 0-based.
constexpr int kCommand = 0;         // write: Command below
constexpr int kStatus = 1;          // read: Status bits below
constexpr int kTargetHi = 2;        // int32 target position in counts: high word at 2, low word at 3
constexpr int kActualHi = 4;        // int32 actual position in counts: high word at 4, low word at 5
constexpr int kVelocityHi = 6;      // int32 profile velocity in counts/s (write), high word first
constexpr int kActualVelocityHi = 8;  // int32 actual velocity in counts/s (read)
constexpr int kFaultCode = 10;      // read: FaultCode below
constexpr int kHeartbeat = 11;      // read: increments every simulator/drive cycle (10 ms)
// Position compare (docs/modbus-register-map.md): the drive pulses its compare output, wired to the
// scanner's trigger input, each time the axis reaches start + k·pitch, k = 0 … count−1.
constexpr int kCompareStartHi = 12;  // int32 first compare position in counts (write)
constexpr int kComparePitchHi = 14;  // int32 pitch in 1/1000 counts, its sign the direction of travel (write)
constexpr int kCompareCount = 16;    // compare positions (write; taken by kArmCompare; 0 disarms)
constexpr int kCompareFired = 17;    // read: pulses fired since the last kArmCompare
constexpr int kCompareTotalHi = 18;  // read: uint32 pulses fired since power-up (a listener on the output's wire
                                     // that polls cannot lose the last pulses of one arming to the next)
constexpr int kStateCount = 12;      // registers 0-11: what a state read takes
constexpr int kCount = 20;

enum Command : std::uint16_t { kNone = 0, kEnable = 1, kDisable = 2, kHome = 3, kMove = 4, kStop = 5, kHalt = 6, kResetFault = 7, kArmCompare = 8 };

enum Status : std::uint16_t {
  kEnabled = 1u << 0,
  kHomed = 1u << 1,
  kMoving = 1u << 2,
  kInPosition = 1u << 3,
  kFault = 1u << 4,
  kLimit = 1u << 5,
};

enum FaultCode : std::uint16_t { kNoFault = 0, kFollowingError = 1, kLimitHit = 2, kNotHomed = 3, kNotEnabled = 4 };

inline void put_i32(std::uint16_t* regs, int hi, std::int32_t v) {
  const auto u = static_cast<std::uint32_t>(v);
  regs[hi] = static_cast<std::uint16_t>(u >> 16);
  regs[hi + 1] = static_cast<std::uint16_t>(u & 0xFFFFu);
}
inline std::int32_t get_i32(const std::uint16_t* regs, int hi) {
  return static_cast<std::int32_t>((static_cast<std::uint32_t>(regs[hi]) << 16) | regs[hi + 1]);
}

}  // namespace scancell::drivers::modbus_map
