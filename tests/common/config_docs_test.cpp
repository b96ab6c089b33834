// Every key of every shipped configuration file is documented: named in docs/*.md or the README (issue 17: a
// parameter's default, range and meaning were in three places and some were in none), and the planner's and
// sensor's key tables state what the shipped files hold.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "common/doc_tables.hpp"
#include "planner/config.hpp"

namespace scancell {
namespace {

namespace fs = std::filesystem;

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Key paths of a YAML tree. The children of `axes` are axis names the cell file chooses, not keys.
void key_paths(const YAML::Node& n, const std::string& prefix, bool names, std::vector<std::string>& out) {
  if (n.IsMap()) {
    for (const auto& kv : n) {
      const std::string k = kv.first.as<std::string>();
      const std::string path = prefix.empty() ? k : prefix + "." + k;
      if (!names) out.push_back(path);
      key_paths(kv.second, path, !names && k == "axes", out);
    }
  } else if (n.IsSequence()) {
    for (const auto& e : n) key_paths(e, prefix + "[]", false, out);
  }
}

TEST(ConfigDocs, EveryShippedKeyIsNamedInTheDocs) {
  const fs::path src = SCANCELL_SOURCE_DIR;
  std::string docs = read(src / "README.md");
  for (const auto& e : fs::directory_iterator(src / "docs"))
    if (e.path().extension() == ".md") docs += read(e.path());
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(src / "config"))
    if (e.path().extension() == ".yaml") files.push_back(e.path());
  ASSERT_GE(files.size(), 9u);
  // Every identifier-like word the documents use.
  std::set<std::string> words;
  const std::regex word("[A-Za-z0-9_]+");
  for (auto it = std::sregex_iterator(docs.begin(), docs.end(), word); it != std::sregex_iterator(); ++it) words.insert(it->str());
  std::size_t checked = 0;
  for (const auto& f : files) {
    std::vector<std::string> paths;
    key_paths(YAML::LoadFile(f.string()), "", false, paths);
    std::set<std::string> missing;
    for (const auto& p : paths) {
      const std::string key = p.substr(p.find_last_of('.') == std::string::npos ? 0 : p.find_last_of('.') + 1);
      const std::string bare = key.substr(0, key.find('['));
      ++checked;
      if (!words.count(bare)) missing.insert(p);
    }
    std::string list;
    for (const auto& m : missing) list += " " + m;
    EXPECT_TRUE(missing.empty()) << fs::relative(f, src).string() << ": keys no document names:" << list;
  }
  EXPECT_GT(checked, 300u);
}

/// The node at a dotted key path, or an undefined node.
YAML::Node at_path(const YAML::Node& root, const std::string& path) {
  YAML::Node n = YAML::Clone(root);
  std::stringstream ss(path);
  std::string part;
  while (std::getline(ss, part, '.')) {
    if (!n.IsMap() || !n[part]) return YAML::Node(YAML::NodeType::Undefined);
    n.reset(n[part]);  // rebind; `n = n[part]` would assign into the tree
  }
  return n;
}

bool same_value(const std::string& a, const std::string& b) {
  char *ea = nullptr, *eb = nullptr;
  const double x = std::strtod(a.c_str(), &ea), y = std::strtod(b.c_str(), &eb);
  if (!a.empty() && !b.empty() && *ea == '\0' && *eb == '\0') return std::abs(x - y) <= 1e-12 * std::max(1.0, std::abs(x));
  return a == b;
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(' '), e = s.find_last_not_of(' ');
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

/// The key table that follows the line naming `file` in `doc`: its `shipped` column must be what the file
/// ships, and every key the file has must have a row (issue 17: a default documented once, checked here).
void expect_table_matches(const std::string& doc, const std::string& heading, const fs::path& file) {
  const YAML::Node y = YAML::LoadFile(file.string());
  std::stringstream in(doc);
  std::string line;
  bool found = false, in_table = false;
  std::set<std::string> rows;
  while (std::getline(in, line)) {
    if (!found) {
      found = line.find(heading) != std::string::npos;
      continue;
    }
    if (line.rfind("| `", 0) != 0) {
      if (in_table) break;
      continue;
    }
    in_table = true;
    const auto k0 = line.find('`'), k1 = line.find('`', k0 + 1);
    const std::string key = line.substr(k0 + 1, k1 - k0 - 1);
    const auto c1 = line.find('|', k1), c2 = line.find('|', c1 + 1);
    const std::string shipped = trim(line.substr(c1 + 1, c2 - c1 - 1));
    rows.insert(key);
    const YAML::Node n = at_path(y, key);
    if (shipped != "—") {
      ASSERT_TRUE(n.IsDefined()) << heading << ": row `" << key << "` names no key of " << file.filename();
    }
    if (shipped == "—") {  // not in the shipped file: its default applies
      EXPECT_FALSE(n.IsDefined()) << heading << ": `" << key << "` documented as not shipped, but " << file.filename() << " sets it";
    } else if (shipped.empty()) {
      EXPECT_TRUE(n.IsMap()) << heading << ": `" << key << "` has no shipped value in the docs but one in the file";
    } else if (n.IsSequence()) {  // a list: written as the file's flow form, [a, b]
      std::string flow = "[";
      for (std::size_t k = 0; k < n.size(); ++k) flow += (k ? ", " : "") + n[k].Scalar();
      EXPECT_EQ(shipped, flow + "]") << heading << ": `" << key << "`";
    } else {
      ASSERT_TRUE(n.IsScalar()) << heading << ": `" << key << "` is not a value in " << file.filename();
      EXPECT_TRUE(same_value(shipped == "\"\"" ? "" : shipped, n.Scalar())) << heading << ": `" << key << "` documented as " << shipped << ", shipped as "
                                                   << n.Scalar();
    }
  }
  ASSERT_TRUE(found) << "no line names " << heading;
  std::vector<std::string> paths;
  key_paths(y, "", false, paths);
  for (const auto& p : paths) {
    if (at_path(y, p).IsMap() || p.find("[]") != std::string::npos) continue;  // a section or a list's entries
    EXPECT_TRUE(rows.count(p)) << heading << ": key " << p << " has no row";
  }
  EXPECT_GT(rows.size(), 10u);
}

TEST(ConfigDocs, TheShippedColumnIsWhatTheFileShips) {
  const fs::path src = SCANCELL_SOURCE_DIR;
  const std::string planner = read(src / "docs" / "planner.md");
  expect_table_matches(planner, "Planner settings, `config/planner/default.yaml`", src / "config" / "planner" / "default.yaml");
  expect_table_matches(planner, "Sensor, `config/sensors/line-scan-thesis.yaml`", src / "config" / "sensors" / "line-scan-thesis.yaml");
  expect_table_matches(read(src / "docs" / "daemon.md"), "## Configuration (`config/scancelld.yaml`", src / "config" / "scancelld.yaml");
}

/// docs/planner.md's settings and sensor tables against what the loaders declare while reading the shipped
/// files (issue 17): each key's default and range are declared once, in the loader call that reads it.
TEST(ConfigDocs, ThePlannerAndSensorDefaultsAndRangesAreWhatTheLoadersDeclare) {
  const fs::path src = SCANCELL_SOURCE_DIR;
  const std::string doc = (src / "docs" / "planner.md").string();
  KeyDeclarations settings;
  planner::load_planner_settings(src / "config" / "planner" / "default.yaml", &settings);
  // Sections (their keys have rows of their own).
  const std::size_t n = test::expect_declared_as_documented(test::doc_table(doc, "Planner settings, `config/planner/default.yaml`"), settings,
                                                            "default, range", {"matrix.free_space_countermeasures", "placement"},
                                                            "docs/planner.md (settings)");
  EXPECT_GE(n, 30u);
  KeyDeclarations sensor;
  planner::load_sensor(src / "config" / "sensors" / "line-scan-thesis.yaml", &sensor);
  // The sensor's ranges are the model's invariants, checked for a model from any source (a sensor file, a
  // plan file, a calibration result: validate(SensorModel)); its table's defaults are the loader's.
  const std::size_t m = test::expect_declared_as_documented(test::doc_table(doc, "Sensor, `config/sensors/line-scan-thesis.yaml`"), sensor,
                                                            "default, range", {}, "docs/planner.md (sensor)", false);
  EXPECT_GE(m, 15u);
}

}  // namespace
}  // namespace scancell
