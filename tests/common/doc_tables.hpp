#pragma once
// The docs' configuration key tables, read as the loaders' declarations are checked against them (issue 17:
// a parameter's default and range are declared once, in the loader call that reads it; the docs say the same
// or a test fails). Header-only: the planner's and the daemon's tests both use it.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/key_declaration.hpp"

namespace scancell::test {

/// One row of a key table: the cells by column name ("key" without its backticks).
struct DocRow {
  int line = 0;
  std::map<std::string, std::string> cells;
  const std::string& at(const std::string& column) const {
    static const std::string none;
    const auto c = cells.find(column);
    return c == cells.end() ? none : c->second;
  }
};

inline std::string trim_cell(const std::string& s) {
  const auto b = s.find_first_not_of(' '), e = s.find_last_not_of(' ');
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

/// Splits a markdown table row on the `|` that are not inside backticks.
inline std::vector<std::string> table_cells(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool code = false;
  for (std::size_t i = 1; i < line.size(); ++i) {
    const char ch = line[i];
    if (ch == '`') code = !code;
    if (ch == '\\' && i + 1 < line.size() && line[i + 1] == '|') {  // an escaped bar is text
      cur += line[++i];
      continue;
    }
    if (ch == '|' && !code) {
      out.push_back(trim_cell(cur));
      cur.clear();
    } else {
      cur += ch;
    }
  }
  return out;
}

/// The table that follows the first line containing `heading` in `file`: its rows by column name.
inline std::vector<DocRow> doc_table(const std::string& file, const std::string& heading) {
  std::ifstream in(file);
  std::string line;
  int n = 0;
  bool found = false;
  std::vector<std::string> columns;
  std::vector<DocRow> rows;
  while (std::getline(in, line)) {
    ++n;
    if (!found) {
      found = line.find(heading) != std::string::npos;
      continue;
    }
    if (line.rfind("|", 0) != 0) {
      if (!columns.empty()) break;
      continue;
    }
    const auto cells = table_cells(line);
    if (columns.empty()) {
      columns = cells;
      continue;
    }
    if (line.rfind("|---", 0) == 0) continue;
    DocRow r;
    r.line = n;
    for (std::size_t k = 0; k < cells.size() && k < columns.size(); ++k) r.cells[columns[k]] = cells[k];
    std::string& key = r.cells["key"];
    key.erase(std::remove(key.begin(), key.end(), '`'), key.end());
    rows.push_back(std::move(r));
  }
  EXPECT_TRUE(found) << file << ": no line names " << heading;
  return rows;
}

/// A number as the docs write one (1e6, π, 0.5235987755982988), or NaN when it is not one.
inline double doc_number(std::string s) {
  s = trim_cell(s);
  if (s == "π") return std::numbers::pi;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  return !s.empty() && *end == '\0' ? v : std::nan("");
}

inline bool same_doc_value(const std::string& doc, const std::string& declared) {
  const double a = doc_number(doc), b = doc_number(declared);
  if (!std::isnan(a) && !std::isnan(b)) return std::abs(a - b) <= 1e-12 * std::max(1.0, std::abs(b));
  const std::string d = doc == "\"\"" ? "" : doc;
  return d == declared;
}

/// Whether the docs' range text states the declared range: "[lo, hi]" and "(0, hi]" bound for bound,
/// "≥ 0" for ">= 0", "> 0" for itself.
inline bool same_doc_range(const std::string& doc, const std::string& declared) {
  std::string d = trim_cell(doc);
  if (d == declared) return true;
  // "0 or [576, 9000]": a value apart from a range; the loader declares the hull, [0, 9000].
  if (const auto alt = d.find(" or ["); alt != std::string::npos && d.find(',', alt) != std::string::npos)
    return same_doc_range("[" + d.substr(0, alt) + "," + d.substr(d.find(',', alt) + 1), declared);
  if (declared == ">= 0") return d == "≥ 0";
  if (declared.size() < 5 || d.size() < 5 || d[0] != declared[0] || d.back() != declared.back()) return false;
  const auto split = [](const std::string& r, std::string& lo, std::string& hi) {
    const auto comma = r.find(',');
    if (comma == std::string::npos) return false;
    lo = r.substr(1, comma - 1);
    hi = r.substr(comma + 1, r.size() - comma - 2);
    return true;
  };
  std::string dl, dh, cl, ch;
  return split(d, dl, dh) && split(declared, cl, ch) && same_doc_value(dl, trim_cell(cl)) && same_doc_value(dh, trim_cell(ch));
}

/// Holds a key table's "default, range" column to what the loader declared while reading the shipped files:
/// - every row names a key the loader declared (except those in `not_read`, keys only other files reach);
/// - its default is the declared fallback ("required" where there is none; "that": the shipped value);
/// - its range, when the row gives one, is the declared range, and a declared range is always given;
/// - every key declared with a range has a row.
/// `check_ranges` false: defaults only (a model whose ranges are its own invariants, checked wherever it comes
/// from). Returns how many rows were compared.
inline std::size_t expect_declared_as_documented(const std::vector<DocRow>& rows, const KeyDeclarations& declared,
                                                 const std::string& column, const std::set<std::string>& not_read,
                                                 const std::string& where, bool check_ranges = true) {
  std::map<std::string, KeyDeclaration> by_path;
  for (const auto& d : declared) by_path[d.path] = d;
  std::set<std::string> documented;
  std::size_t compared = 0;
  for (const auto& r : rows) {
    const std::string& key = r.at("key");
    documented.insert(key);
    const auto d = by_path.find(key);
    if (d == by_path.end()) {
      EXPECT_TRUE(not_read.count(key)) << where << ":" << r.line << ": `" << key << "` is documented, but no loader call read it";
      continue;
    }
    std::string text = trim_cell(r.at(column));
    if (text.empty()) {
      ADD_FAILURE() << where << ":" << r.line << ": `" << key << "` has no '" << column << "'; the loader declares "
                    << d->second.fallback << (d->second.range.empty() ? "" : ", " + d->second.range);
      continue;
    }
    // "`genicam`: 0, [0, 1023]": a default that depends on another key; its range is still the loader's.
    const bool conditional = text[0] == '`' && text.find("`: ") != std::string::npos;
    if (conditional) text = text.substr(text.rfind("`: ") + 3);
    std::string def = text, range;
    int depth = 0;
    for (std::size_t i = 0; i + 1 < text.size(); ++i) {
      depth += (text[i] == '(' || text[i] == '[') - (text[i] == ')' || text[i] == ']');
      if (depth == 0 && text[i] == ',' && text[i + 1] == ' ') {
        def = text.substr(0, i);
        range = text.substr(i + 2);
        break;
      }
    }
    if (const auto note = def.find(" ("); note != std::string::npos) def = def.substr(0, note);  // "daemon (daemon, drive_compare)"
    if (const auto note = range.find(" ("); note != std::string::npos) range = range.substr(0, note);  // "≥ 0 (when …)"
    if (def == "that") def = r.at("shipped");
    // "= `range_min_mm`", "= the file's name": a default taken from elsewhere, not a value of its own.
    const bool derived = def.rfind("=", 0) == 0;
    ++compared;
    if (!conditional && !derived) {
      EXPECT_TRUE(same_doc_value(def, d->second.fallback))
          << where << ":" << r.line << ": `" << key << "` documented default " << def << ", the loader's " << d->second.fallback;
    }
    if (!d->second.range.empty() && check_ranges) {
      EXPECT_TRUE(same_doc_range(range, d->second.range))
          << where << ":" << r.line << ": `" << key << "` documented range '" << range << "', the loader's " << d->second.range;
    }
  }
  for (const auto& d : declared)
    if (!d.range.empty()) {
      EXPECT_TRUE(documented.count(d.path)) << where << ": `" << d.path << "` (default " << d.fallback << ", " << d.range
                                            << ") is declared by the loader but has no row";
    }
  return compared;
}

}  // namespace scancell::test
