// scancell: command-line front end of the planner.
//   scancell plan --mesh M --sensor S --spec P [--settings X] --out plan.json [options]
#include <charconv>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "planner/errors.hpp"
#include "planner/plan.hpp"

namespace sp = scancell::planner;

namespace {

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

const char* kPlanUsage =
    "usage: scancell plan --mesh FILE --sensor SENSOR.yaml --spec SPEC.yaml --out PLAN.json [options]\n"
    "  --settings FILE.yaml      planner settings (viewpoints, cover, matrix); defaults if omitted\n"
    "  --scale K                 multiply mesh coordinates by K to get mm\n"
    "  --fit-mm L                scale so the longest bounding-box side is L mm\n"
    "  --rough-vertices N        quadric-decimate the rough model to N vertices\n"
    "  --rho-rel R               decimate to 2^R times the input vertex count (R <= 0, thesis 5.3)\n"
    "  --rough-noise-mm SIGMA    Gaussian displacement along the normal (thesis 5.4)\n"
    "  --seed N                  seed for the noise (default: settings seed)\n"
    "  --segments FILE           surface patch label per mesh vertex (integers, -1 none), in vertex order\n"
    "                            after welding; adds single-best-view candidates per patch (thesis 6.3.4)\n"
    "  --cover greedy|constrained   override the settings' cover mode\n"
    "  --threads N               worker threads (default all cores; the plan does not depend on it)\n"
    "  --quiet                   no summary table\n";

/// Simple --key value parser that refuses unknown or repeated options.
std::map<std::string, std::string> parse(int argc, char** argv, const std::vector<std::string>& with_value,
                                         const std::vector<std::string>& flags) {
  std::map<std::string, std::string> out;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    auto is = [&](const std::vector<std::string>& v) { return std::find(v.begin(), v.end(), a) != v.end(); };
    if (out.count(a)) throw UsageError("option " + a + " given twice");
    if (is(flags)) {
      out[a] = "1";
    } else if (is(with_value)) {
      if (i + 1 >= argc) throw UsageError("option " + a + " needs a value");
      out[a] = argv[++i];
    } else {
      throw UsageError("unknown option '" + a + "'");
    }
  }
  return out;
}

double number(const std::map<std::string, std::string>& o, const std::string& key) {
  const std::string& s = o.at(key);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || !std::isfinite(v)) throw UsageError(key + ": '" + s + "' is not a finite number");
  return v;
}

std::uint64_t whole(const std::map<std::string, std::string>& o, const std::string& key) {
  const std::string& s = o.at(key);
  std::uint64_t v = 0;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size()) throw UsageError(key + ": '" + s + "' is not a whole number >= 0");
  return v;
}

int cmd_plan(int argc, char** argv) {
  const auto o = parse(argc, argv,
                       {"--mesh", "--sensor", "--spec", "--settings", "--out", "--scale", "--fit-mm", "--rough-vertices",
                        "--rho-rel", "--rough-noise-mm", "--seed", "--cover", "--threads", "--segments"},
                       {"--quiet"});
  for (const char* k : {"--mesh", "--sensor", "--spec", "--out"})
    if (!o.count(k)) throw UsageError(std::string("missing ") + k);
  if (o.count("--scale") && o.count("--fit-mm")) throw UsageError("give --scale or --fit-mm, not both");

  const sp::SensorModel sensor = sp::load_sensor(o.at("--sensor"));
  const sp::ModelSpec spec = sp::load_spec(o.at("--spec"));
  sp::PlannerSettings settings = o.count("--settings") ? sp::load_planner_settings(o.at("--settings")) : sp::PlannerSettings{};
  if (o.count("--cover")) {
    const std::string& m = o.at("--cover");
    if (m == "greedy") settings.cover.mode = sp::CoverMode::greedy;
    else if (m == "constrained") settings.cover.mode = sp::CoverMode::constrained;
    else throw UsageError("--cover: '" + m + "' is not greedy or constrained");
  }
  sp::RoughModelOptions rough;
  if (o.count("--rough-vertices")) rough.target_vertices = whole(o, "--rough-vertices");
  if (o.count("--rho-rel")) rough.rho_rel = number(o, "--rho-rel");
  if (o.count("--rough-noise-mm")) rough.normal_noise_mm = number(o, "--rough-noise-mm");
  if (o.count("--seed")) settings.seed = whole(o, "--seed");
  rough.seed = settings.seed;
  const int threads = o.count("--threads") ? static_cast<int>(whole(o, "--threads")) : 0;

  sp::ObjectSource source;
  source.mesh_path = o.at("--mesh");
  sp::TriangleMesh mesh = sp::load_mesh(source.mesh_path, &source.load);
  if (source.load.degenerate_dropped)
    std::cerr << "scancell: " << source.mesh_path << ": dropped " << source.load.degenerate_dropped << " degenerate triangles\n";
  if (o.count("--scale")) {
    source.scale = number(o, "--scale");
    if (!(source.scale > 0.0)) throw UsageError("--scale must be > 0");
  } else if (o.count("--fit-mm")) {
    const double l = number(o, "--fit-mm");
    if (!(l > 0.0)) throw UsageError("--fit-mm must be > 0");
    source.scale = sp::fit_scale(mesh, l);
  }
  sp::apply_scale(mesh, source.scale);
  if (o.count("--segments")) {
    const std::string& f = o.at("--segments");
    std::ifstream in(f);
    if (!in) throw UsageError("--segments: cannot open " + f);
    std::string tok;
    for (std::size_t k = 0; in >> tok; ++k) {
      int v = 0;
      auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
      if (ec != std::errc() || p != tok.data() + tok.size() || v < -1)
        throw UsageError(f + ": label " + std::to_string(k) + " '" + tok + "' is not an integer >= -1");
      rough.vertex_labels.push_back(v);
    }
    if (rough.vertex_labels.size() != mesh.vertices.size())
      throw UsageError(f + ": " + std::to_string(rough.vertex_labels.size()) + " labels for " +
                       std::to_string(mesh.vertices.size()) + " mesh vertices");
  }

  sp::ViewPlan plan = sp::plan_views(std::move(mesh), sensor, spec, settings, rough, threads);
  plan.object = source;
  if (plan.rough_report.faces_rejected_by_decimator)
    std::cerr << "scancell: decimator rejected " << plan.rough_report.faces_rejected_by_decimator << " non-manifold faces\n";

  // Write to a temporary file and rename, so a reader never sees half a plan.
  const std::string out = o.at("--out");
  const std::string tmp = out + ".tmp";
  {
    std::ofstream f(tmp, std::ios::trunc);
    if (!f) throw std::runtime_error(out + ": cannot open for writing");
    f << sp::plan_to_json(plan).dump(2) << '\n';
    if (!f.flush()) throw std::runtime_error(out + ": write failed");
  }
  if (std::rename(tmp.c_str(), out.c_str()) != 0) throw std::runtime_error(out + ": cannot rename " + tmp + ": " + std::strerror(errno));
  if (!o.count("--quiet")) std::cout << sp::plan_summary(plan);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::cerr << "usage: scancell COMMAND [options]\ncommands:\n  plan    plan the views that measure an object to a specification\n\n"
              << kPlanUsage;
    return argc < 2 ? 2 : 0;
  }
  const std::string cmd = argv[1];
  try {
    if (cmd == "plan") {
      if (argc == 3 && (!std::strcmp(argv[2], "--help") || !std::strcmp(argv[2], "-h"))) {
        std::cout << kPlanUsage;
        return 0;
      }
      return cmd_plan(argc - 2, argv + 2);
    }
    std::cerr << "scancell: unknown command '" << cmd << "'\n";
    return 2;
  } catch (const UsageError& e) {
    std::cerr << "scancell " << cmd << ": " << e.what() << "\n" << kPlanUsage;
    return 2;
  } catch (const sp::MeshError& e) {
    std::cerr << "scancell: mesh error: " << e.what() << "\n";
    return 3;
  } catch (const sp::ConfigError& e) {
    std::cerr << "scancell: config error: " << e.what() << "\n";
    return 4;
  } catch (const std::exception& e) {
    std::cerr << "scancell: error: " << e.what() << "\n";
    return 1;
  }
}
