#pragma once
// Pictures people read, drawn by gnuplot (pngcairo): a scratch directory for the data files, gnuplot's
// quoting, and the run that writes a PNG whole (temporary file, rename) or throws naming what failed.
// Needs gnuplot on the PATH (Debian: gnuplot-nox, installed by scripts/deps.sh).
#include <filesystem>
#include <string>

namespace scancell {

/// A scratch directory for a picture's data files, removed on every way out.
struct ScratchDir {
  std::filesystem::path path;
  explicit ScratchDir(const std::string& prefix = "scancell-picture");
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
};

/// gnuplot's single-quoted string (file names): a quote is doubled; a newline is refused (std::runtime_error).
std::string gnuplot_quoted(const std::string& s);

/// gnuplot's double-quoted string (titles, labels): backslash and quote escaped, a newline becomes a line break.
std::string gnuplot_text(const std::string& s);

/// Runs gnuplot: `terminal` (e.g. "pngcairo size 1600,820 font 'sans,10'"), the output set to a temporary
/// file beside `png`, then `script`, which draws; renames the file to `png`. `what` names the picture in
/// errors (std::runtime_error: gnuplot missing, failed, or wrote nothing).
void run_gnuplot(const std::string& terminal, const std::string& script, const std::filesystem::path& png,
                 const std::string& what);

}  // namespace scancell
