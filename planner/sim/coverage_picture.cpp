#include <sstream>

#include "common/gnuplot.hpp"
#include "planner/sim/verify.hpp"

namespace scancell::planner {

std::string write_coverage_picture(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                                   const std::string& title, const std::filesystem::path& png) {
  const ScratchDir dir("scancell-coverage-png");
  const int tile = 320;
  const auto tiles = dir.path / "tiles.png";
  write_measurability_png(mesh, measured, tiles, tile);
  // The tiles' order and layout as write_measurability_png draws them: 3 across, 2 down.
  const char* names[6] = {"from +X", "from -X", "from +Y", "from -Y", "from +Z (above)", "from -Z (below)"};
  std::ostringstream s;
  s << "set title " << gnuplot_text(title) << " font ',12' noenhanced\n"
    << "unset border\nunset tics\nunset xlabel\nunset ylabel\nset size ratio -1\n"
    << "set xrange [0:" << 3 * tile << "]\nset yrange [0:" << 2 * tile << "]\n"
    << "set key outside bottom center horizontal samplen 1 font ',10'\n"
    << "set style textbox opaque fc rgb '#23272f' noborder\n";
  for (int t = 0; t < 6; ++t)
    s << "set label " << t + 1 << " '" << names[t] << "' at " << (t % 3) * tile + tile / 2 << "," << 2 * tile - (t / 3) * tile - 14
      << " center front boxed tc rgb 'white' font ',11'\n";
  s << "plot " << gnuplot_quoted(tiles.string()) << " binary filetype=png with rgbimage notitle, "
    << "NaN w p pt 5 ps 2 lc rgb '#b4b4b4' t 'measured to the spec (shaded by the surface normal)', "
    << "NaN w p pt 5 ps 2 lc rgb '#d0403a' t 'not measured to the spec'\n";
  try {
    run_gnuplot("pngcairo size 1240,860 font 'sans,10'", s.str(), png, "coverage picture");
    return "";
  } catch (const std::exception& e) {
    // The views already rendered, bare: the caller says so.
    std::filesystem::copy_file(tiles, png, std::filesystem::copy_options::overwrite_existing);
    return std::string(e.what()) + "; the picture has no legend or title";
  }
}

}  // namespace scancell::planner
