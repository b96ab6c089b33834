#pragma once
// `scancell plan --png`: the plan as a picture people read (issue 19), drawn by gnuplot (pngcairo).
#include <filesystem>
#include <string>

#include "planner/plan.hpp"

namespace scancell::tools {

/// Two panels, a perspective view and the view from above: the rough model's rows (blue where the plan's
/// views are predicted to measure them, red where not), each view's camera numbered in execution order,
/// its boresight to the targeted surface and its scan path (the sweep, L_y long). Titled with the object,
/// the view count, the predicted area and the spec. Needs gnuplot on the PATH (scripts/deps.sh installs
/// gnuplot-nox); std::runtime_error naming what failed otherwise. Written whole (temporary file, rename).
void write_plan_png(const planner::ViewPlan& plan, const std::string& name, const std::filesystem::path& png);

}  // namespace scancell::tools
