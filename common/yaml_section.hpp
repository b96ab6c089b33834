#pragma once
// A YAML mapping that knows its file and key path and which keys were read, so that every config loader
// refuses unknown keys and names "file: key.path: why" for anything wrong. Shared by the planner's and the
// drivers' configuration.
#include <cmath>
#include <filesystem>
#include <charconv>
#include <type_traits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/yaml.h>

#include "common/errors.hpp"
#include "common/key_declaration.hpp"
#include "common/text_file.hpp"

namespace scancell {

/// A YAML mapping that knows its key path and which keys were read, so unknown keys can be refused.
class Section {
 public:
  Section(YAML::Node node, std::string file, std::string path, KeyDeclarations* declared = nullptr)
      : node_(std::move(node)), file_(std::move(file)), path_(std::move(path)), declared_(declared) {
    if (!node_.IsMap()) fail(path_.empty() ? "<root>" : path_, "must be a mapping");
  }

  /// Records what the loader declares for `key` (when a caller asked for declarations); a later declaration
  /// of the same key replaces an earlier one (a helper that reads with `get` and then declares its range).
  void declare(const std::string& key, const std::string& fallback, const std::string& range) {
    if (!declared_) return;
    const std::string path = key_path(key);
    for (auto& d : *declared_)
      if (d.path == path) {
        d = {path, fallback, range};
        return;
      }
    declared_->push_back({path, fallback, range});
  }
  /// A declared value as text: the shortest form that reads back as the same number (0.07, not
  /// 0.070000000000000007).
  template <class T>
  static std::string text_of(const T& v) {
    if constexpr (std::is_same_v<T, bool>) {
      return v ? "true" : "false";
    } else if constexpr (std::is_arithmetic_v<T>) {
      char b[64];
      const auto r = std::to_chars(b, b + sizeof b, v);
      return std::string(b, r.ptr);
    } else {
      std::ostringstream os;
      os << v;
      return os.str();
    }
  }

  [[noreturn]] void fail(const std::string& key, const std::string& why) const {
    throw ConfigError(file_ + ": " + key + ": " + why);
  }
  std::string key_path(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  bool has(const std::string& key) const { return static_cast<bool>(node_[key]); }

  template <class T>
  T get(const std::string& key) {
    declare(key, "required", "");
    return read<T>(key);
  }
  template <class T>
  T get_or(const std::string& key, T fallback) {
    declare(key, text_of(fallback), "");
    return value_or<T>(key, fallback);
  }
  Section section(const std::string& key) {
    used_.insert(key);
    const YAML::Node n = node_[key];
    if (!n) fail(key_path(key), "missing");
    return Section(n, file_, key_path(key), declared_);
  }
  double positive(const std::string& key) {
    declare(key, "required", "> 0");
    const double v = read<double>(key);
    if (!(v > 0.0)) fail(key_path(key), "must be > 0, got " + std::to_string(v));
    return v;
  }
  Eigen::Vector3d vec3(const std::string& key) {
    used_.insert(key);
    const YAML::Node n = node_[key];
    if (!n) fail(key_path(key), "missing");
    if (!n.IsSequence() || n.size() != 3) fail(key_path(key), "must be a list of 3 numbers");
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) {
      try {
        v[k] = n[k].as<double>();
      } catch (const YAML::Exception&) {
        fail(key_path(key), "element " + std::to_string(k) + " is not a number");
      }
      if (!std::isfinite(v[k])) fail(key_path(key), "element " + std::to_string(k) + " must be finite");
    }
    return v;
  }
  std::vector<std::string> keys() const {
    std::vector<std::string> out;
    for (const auto& kv : node_) out.push_back(kv.first.as<std::string>());
    return out;
  }
  YAML::Node raw(const std::string& key) {
    used_.insert(key);
    return node_[key];
  }
  const std::string& file() const { return file_; }
  double non_negative(const std::string& key, double fallback) {
    declare(key, text_of(fallback), ">= 0");
    const double v = value_or<double>(key, fallback);
    if (!(v >= 0.0)) fail(key_path(key), "must be >= 0, got " + std::to_string(v));
    return v;
  }
  /// The key's default and its closed range in one call: absent gives `fallback`, outside [lo, hi] is refused
  /// naming the value.
  template <class T>
  T ranged(const std::string& key, T fallback, T lo, T hi) {
    declare(key, text_of(fallback), "[" + text_of(lo) + ", " + text_of(hi) + "]");
    const T v = value_or<T>(key, fallback);
    if (!(v >= lo && v <= hi)) {
      std::ostringstream os;
      os << "must be in [" << lo << ", " << hi << "], got " << v;
      fail(key_path(key), os.str());
    }
    return v;
  }
  /// The same with `hi` itself refused, [lo, hi): a limit the value must stay under (an angle short of π/2).
  double ranged_below(const std::string& key, double fallback, double lo, double hi) {
    declare(key, text_of(fallback), "[" + text_of(lo) + ", " + text_of(hi) + ")");
    const double v = value_or<double>(key, fallback);
    if (!(v >= lo && v < hi)) {
      std::ostringstream os;
      os << "must be in [" << lo << ", " << hi << "), got " << v;
      fail(key_path(key), os.str());
    }
    return v;
  }
  /// A positive value up to `hi`, (0, hi]: absent gives `fallback`; 0 would mean "none at all", not "no limit".
  double positive_up_to(const std::string& key, double fallback, double hi) {
    declare(key, text_of(fallback), "(0, " + text_of(hi) + "]");
    const double v = value_or<double>(key, fallback);
    if (!(v > 0.0 && v <= hi)) {
      std::ostringstream os;
      os << "must be in (0, " << hi << "], got " << v;
      fail(key_path(key), os.str());
    }
    return v;
  }
  /// Refuses keys nobody asked for: a typo must not silently fall back to a default.
  void finish() const {
    for (const auto& kv : node_) {
      const std::string k = kv.first.as<std::string>();
      if (!used_.count(k)) fail(key_path(k), "unknown key");
    }
  }

 private:
  template <class T>
  T read(const std::string& key) {
    used_.insert(key);
    const YAML::Node n = node_[key];
    if (!n) fail(key_path(key), "missing");
    return convert<T>(n, key);
  }
  template <class T>
  T value_or(const std::string& key, T fallback) {
    return has(key) ? read<T>(key) : fallback;
  }
  template <class T>
  T convert(const YAML::Node& n, const std::string& key) const {
    try {
      if constexpr (std::is_floating_point_v<T>) {
        const T v = n.as<T>();
        if (!std::isfinite(v)) fail(key_path(key), "must be a finite number");
        return v;
      } else {
        return n.as<T>();
      }
    } catch (const YAML::Exception&) {
      std::ostringstream os;
      os << "cannot read '" << (n.IsScalar() ? n.Scalar() : std::string("<non-scalar>")) << "' as "
         << (std::is_floating_point_v<T> ? "a number" : std::is_integral_v<T> ? "an integer" : "a string");
      fail(key_path(key), os.str());
    }
  }

  YAML::Node node_;
  std::string file_, path_;
  std::set<std::string> used_;
  KeyDeclarations* declared_ = nullptr;  // where declare() records, when a caller asked (tests); not owned
};

/// Configuration files are small; anything larger is not one (and is not read into memory).
inline constexpr std::size_t kMaxConfigBytes = 4 * 1024 * 1024;

/// YAML text parsed into `holder`; every parser error becomes a ConfigError naming `where` and the line
/// (`format` says what the text was meant to be), and nesting past yaml-cpp's depth guard is named as such.
inline void load_yaml_text(const std::string& text, const std::string& where, const char* format, YAML::Node& holder) {
  try {
    holder = YAML::Load(text);
  } catch (const YAML::DeepRecursion& e) {
    throw ConfigError(where + ": nested deeper than a configuration ever needs, at line " + std::to_string(e.mark.line + 1));
  } catch (const YAML::Exception& e) {
    throw ConfigError(where + ": invalid " + format + " at line " + std::to_string(e.mark.line + 1) + ", column " +
                      std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
}

inline Section open_root(const std::filesystem::path& file, YAML::Node& holder, KeyDeclarations* declared = nullptr) {
  // Read through read_regular_file: a FIFO or device named as a config is refused, never waited on.
  load_yaml_text(read_regular_file(file, kMaxConfigBytes), file.string(), "YAML", holder);
  if (!holder || holder.IsNull()) throw ConfigError(file.string() + ": file is empty");
  return Section(holder, file.string(), "", declared);
}

inline Section parse_root(const std::string& text, const std::string& where, YAML::Node& holder) {
  load_yaml_text(text, where, "YAML/JSON", holder);
  if (!holder || holder.IsNull()) throw ConfigError(where + ": empty");
  return Section(holder, where, "");
}


}  // namespace scancell
