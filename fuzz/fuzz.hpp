#pragma once
// Shared by the fuzz targets: a file holding the input (the loaders read files, as the daemon does), and the
// rule every target checks — bad input ends in the loader's documented error type, never in anything else
// (another exception escapes the target and libFuzzer or the replay reports it, as it does a crash).
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

namespace scancell::fuzz {

/// The input written to a file of this process named `name` (overwritten each call).
inline std::filesystem::path as_file(const std::string& name, const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path dir = [] {
    auto d = std::filesystem::temp_directory_path() / ("scancell-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  const auto path = dir / name;
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return path;
}

}  // namespace scancell::fuzz
