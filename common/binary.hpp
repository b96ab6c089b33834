#pragma once
// Little-endian binary records (the PLY bodies of range images, clouds and models).
#include <bit>
#include <cstring>
#include <string>

namespace scancell {

static_assert(std::endian::native == std::endian::little, "scancell writes little-endian files on a little-endian host");

/// Appends `v`'s bytes to `buf`.
template <class T>
void append_binary(std::string& buf, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  buf.append(b, sizeof(T));
}

}  // namespace scancell
