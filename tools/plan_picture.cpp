#include "tools/plan_picture.hpp"
#include "common/gnuplot.hpp"

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <vector>
#include <stdexcept>

namespace scancell::tools {

namespace fs = std::filesystem;

void write_plan_png(const planner::ViewPlan& plan, const std::string& name, const fs::path& png) {
  const ScratchDir dir("scancell-plan-png");
  std::vector<std::uint8_t> predicted(plan.rough.size(), 0);
  for (const auto r : plan.predicted_rows)
    if (r < predicted.size()) predicted[r] = 1;
  std::ofstream in(dir.path / "in.dat"), out(dir.path / "out.dat"), bore(dir.path / "bore.dat"), sweep(dir.path / "sweep.dat"),
      cams(dir.path / "cams.dat");
  std::size_t n_in = 0;
  double area_in = 0.0;
  for (std::size_t r = 0; r < plan.rough.size(); ++r) {
    const auto& p = plan.rough.points[r];
    (predicted[r] ? in : out) << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
    if (predicted[r]) ++n_in, area_in += plan.rough.area_mm2[r];
  }
  for (std::size_t k = 0; k < plan.views.size(); ++k) {
    const planner::Viewpoint& v = plan.views[k];
    const Eigen::Vector3d target = v.position + v.standoff_mm * v.axis;
    const Eigen::Vector3d y = v.rotation().col(1) * (0.5 * v.scan_length_mm);
    // Two blank lines end a data set: each segment stands alone (one blank line would join them into a grid).
    bore << v.position.transpose() << '\n' << target.transpose() << "\n\n\n";
    sweep << (v.position - y).transpose() << '\n' << (v.position + y).transpose() << "\n\n\n";
    cams << v.position.transpose() << ' ' << k + 1 << '\n';
  }
  for (auto* f : {&in, &out, &bore, &sweep, &cams})
    if (!f->flush()) throw std::runtime_error("--png: cannot write the picture's data in " + dir.path.string());
  in.close(), out.close(), bore.close(), sweep.close(), cams.close();
  // gnuplot's 'with points' refuses an empty file: a placeholder point far outside is never drawn (NaN).
  for (const char* f : {"in.dat", "out.dat", "bore.dat", "sweep.dat", "cams.dat"})
    if (fs::file_size(dir.path / f) == 0) std::ofstream(dir.path / f) << "NaN NaN NaN 0\n";

  char title[512];
  std::snprintf(title, sizeof title, "%s: %zu views, predicted to measure %.0f of %.0f mm² (%.1f %%), spec %g mm, %g samples/mm²",
                name.c_str(), plan.views.size(), area_in, plan.rough.total_area_mm2,
                plan.rough.total_area_mm2 > 0 ? 100.0 * area_in / plan.rough.total_area_mm2 : 0.0, plan.spec.precision_mm,
                plan.spec.density_per_mm2);
  const auto d = [&](const char* f) { return gnuplot_quoted((dir.path / f).string()); };
  std::ostringstream s;
  s << "set multiplot layout 1,2 title " << gnuplot_text(title) << " font ',12' noenhanced\n"
    << "set xlabel 'x (mm)'\nset ylabel 'y (mm)'\nset zlabel 'z (mm)' rotate parallel\nset view equal xyz\n"
    << "set key bottom center horizontal samplen 2 font ',9'\nset ticslevel 0\n"
    << "plot_it = \"splot " << d("in.dat") << " w p pt 7 ps 0.25 lc rgb '#3b7dd8' t 'rows predicted measured (" << n_in << ")', "
    << d("out.dat") << " w p pt 7 ps 0.35 lc rgb '#d0403a' t 'rows left (" << plan.rough.size() - n_in << ")', "
    << d("bore.dat") << " w l dt 2 lc rgb '#777777' t 'boresight', "
    << d("sweep.dat") << " w l lw 3 lc rgb '#2a9d3a' t 'scan path', "
    << d("cams.dat") << " u 1:2:3:4 w labels point pt 7 ps 0.7 lc rgb 'black' offset 0,0.9 font ',9' t 'camera, execution order'\"\n"
    << "set title 'perspective'\nset view 62,32\neval plot_it\n"
    << "set title 'from above (+z)'\nset view 0,0\nunset zlabel\nunset ztics\neval plot_it\n"
    << "unset multiplot\n";
  run_gnuplot("pngcairo size 1600,820 font 'sans,10'", s.str(), png, "--png");
}

}  // namespace scancell::tools
