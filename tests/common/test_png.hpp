#pragma once
// A picture the tests check: a whole PNG of the expected size, drawn, with no .tmp left beside it.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace scancell::test_support {

/// The signature, the IHDR width and height, more than `min_bytes` (a drawn picture, not an empty frame).
inline void expect_whole_png(const std::string& file, std::uint32_t width, std::uint32_t height, std::uintmax_t min_bytes) {
  std::ifstream png(file, std::ios::binary);
  std::string head(24, '\0');
  ASSERT_TRUE(png.read(head.data(), 24)) << file;
  EXPECT_EQ(head.substr(1, 3), "PNG") << file;
  auto be32 = [&](int at) {
    return (std::uint32_t(std::uint8_t(head[at])) << 24) | (std::uint32_t(std::uint8_t(head[at + 1])) << 16) |
           (std::uint32_t(std::uint8_t(head[at + 2])) << 8) | std::uint32_t(std::uint8_t(head[at + 3]));
  };
  EXPECT_EQ(be32(16), width) << file;
  EXPECT_EQ(be32(20), height) << file;
  EXPECT_GT(std::filesystem::file_size(file), min_bytes) << file;
  EXPECT_FALSE(std::filesystem::exists(file + ".tmp")) << file;
}

}  // namespace scancell::test_support
