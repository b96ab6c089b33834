// The gnuplot runner behind every picture: a missing or failing gnuplot is an error that names it, never a
// signal that ends the process, and never a half-written picture.
#include <cstdlib>
#include <filesystem>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/gnuplot.hpp"

namespace scancell {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

TEST(Gnuplot, AMissingGnuplotIsAnErrorNamingItNotASignal) {
  const ScratchDir dir("scancell-gnuplot-test");
  const std::string old_path = std::getenv("PATH") ? std::getenv("PATH") : "";
  setenv("PATH", dir.path.c_str(), 1);  // an empty directory: no gnuplot
  // 1 MB of script: far more than a pipe holds, so the write meets the closed pipe (EPIPE, or SIGPIPE unblocked).
  const std::string script(1 << 20, '#');
  try {
    run_gnuplot("pngcairo size 100,100", script + "\nplot x\n", dir.path / "p.png", "test picture");
    ADD_FAILURE() << "drew without gnuplot";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("test picture needs gnuplot on the PATH"));
  }
  setenv("PATH", old_path.c_str(), 1);
  EXPECT_FALSE(fs::exists(dir.path / "p.png"));
  EXPECT_FALSE(fs::exists(dir.path / "p.png.tmp"));
}

TEST(Gnuplot, AScriptGnuplotRefusesIsAnErrorAndLeavesNoFile) {
  const ScratchDir dir("scancell-gnuplot-test");
  try {
    run_gnuplot("pngcairo size 100,100", "plot no_such_function(x)\n", dir.path / "p.png", "test picture");
    ADD_FAILURE() << "accepted a bad script";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("test picture: gnuplot failed"));
  }
  EXPECT_FALSE(fs::exists(dir.path / "p.png"));
  EXPECT_FALSE(fs::exists(dir.path / "p.png.tmp"));
  // And a good one is written whole under its name.
  run_gnuplot("pngcairo size 120,80", "plot x\n", dir.path / "p.png", "test picture");
  EXPECT_GT(fs::file_size(dir.path / "p.png"), 100u);
  EXPECT_EQ(gnuplot_text("a \"b\"\nc"), "\"a \\\"b\\\"\\nc\"");
  EXPECT_EQ(gnuplot_quoted("it's"), "'it''s'");
}

}  // namespace
}  // namespace scancell
