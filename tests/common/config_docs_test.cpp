// Every key of every shipped configuration file is documented: named in docs/*.md or the README (issue 17: a
// parameter's default, range and meaning were in three places and some were in none).
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

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

}  // namespace
}  // namespace scancell
