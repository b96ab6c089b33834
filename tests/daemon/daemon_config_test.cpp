// docs/daemon.md's configuration table against what load_daemon_config declares while it reads the shipped
// files (issue 17): every key's default and range are declared once, in the loader call that reads it, and
// the table states the same.
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "daemon/daemon_config.hpp"
#include "common/doc_tables.hpp"

namespace scancell::daemon {
namespace {

namespace fs = std::filesystem;

/// The shipped config/scancelld.yaml as it would load on a cell: its files named absolutely, and its
/// allowed_dirs (/var/lib/scancell/inbox, absent here) a directory of the test's.
fs::path shipped_config_here(const fs::path& src, const fs::path& dir) {
  YAML::Node y = YAML::LoadFile((src / "config" / "scancelld.yaml").string());
  for (const char* k : {"cell", "drivers", "sensor", "spec", "planner"}) y[k] = (src / "config" / y[k].as<std::string>()).string();
  fs::create_directories(dir / "inbox");
  y["jobs"]["allowed_dirs"] = std::vector<std::string>{(dir / "inbox").string()};
  const fs::path out = dir / "scancelld.yaml";
  std::ofstream(out) << y;
  return out;
}

TEST(DaemonConfigDocs, TheDefaultAndRangeColumnIsWhatTheLoaderDeclares) {
  const fs::path src = SCANCELL_SOURCE_DIR;
  // The shipped file, the demo's and the GigE demo's: between them every scanner driver the table's keys
  // need, and a truth section.
  const fs::path dir = fs::temp_directory_path() / "scancell_daemon_config_docs";
  KeyDeclarations declared;
  for (const fs::path& f : {shipped_config_here(src, dir), src / "config/demo/scancelld.yaml", src / "config/demo/scancelld-gige.yaml"}) {
    KeyDeclarations one;
    load_daemon_config(f, dir.string(), (dir / "control.sock").string(), &one);
    for (const auto& d : one) {
      bool seen = false;
      for (const auto& e : declared) seen = seen || e.path == d.path;
      if (!seen) declared.push_back(d);
    }
  }
  // Keys no loader call declares: lists read whole (their entries are checked one by one), and the keys of a
  // real scanner's trigger line, which only `driver: genicam` reads.
  const std::set<std::string> undeclared{"calibration", "rough_scan.tilts_rad", "jobs.allowed_dirs", "scanner.truth",
                                         "scanner.trigger.chip", "scanner.trigger.offset"};
  const auto rows = test::doc_table((src / "docs" / "daemon.md").string(), "## Configuration (`config/scancelld.yaml`");
  const std::size_t compared = test::expect_declared_as_documented(rows, declared, "default, range", undeclared, "docs/daemon.md");
  EXPECT_GT(compared, 40u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace scancell::daemon
