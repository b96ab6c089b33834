#pragma once
// What a config loader declares about one key in the call that reads it (common/yaml_section.hpp). A
// parameter's default and range are declared once, in that call (issue 17); tests hold the docs' key tables
// to these declarations, so a default or range changed in one place and not the other fails.
#include <string>
#include <vector>

namespace scancell {

/// `path`: the key path ("jobs.max_rounds"); `fallback`: the value applied when the key is absent, or
/// "required"; `range`: the values accepted, "[lo, hi]", "(0, hi]", "> 0", ">= 0", or "" for any value of
/// the key's type.
struct KeyDeclaration {
  std::string path, fallback, range;
};
using KeyDeclarations = std::vector<KeyDeclaration>;

}  // namespace scancell
