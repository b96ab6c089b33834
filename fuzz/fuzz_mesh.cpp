// Mesh loading, all four formats: the first byte picks OFF, PLY, STL or OBJ, the rest is the file. Every bad
// file must end in MeshError (load_mesh parses in a child with a time limit: a parser that loops or crashes
// is a MeshError too).
#include <chrono>

#include "fuzz/fuzz.hpp"
#include "common/errors.hpp"
#include "planner/geometry/mesh.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* const kExt[] = {"in.off", "in.ply", "in.stl", "in.obj"};
  const auto path = scancell::fuzz::as_file(kExt[data[0] % 4], data + 1, size - 1);
  try {
    scancell::planner::load_mesh(path, nullptr, std::chrono::milliseconds(2000));
  } catch (const scancell::MeshError&) {
  }
  return 0;
}
