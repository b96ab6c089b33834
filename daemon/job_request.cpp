#include "daemon/job_request.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "planner/config.hpp"

namespace scancell::daemon {

namespace sp = scancell::planner;
using nlohmann::json;

sp::TriangleMesh load_object(const std::string& path, double fit_mm, const std::atomic<int>* cancel) {
  sp::TriangleMesh m = sp::load_mesh(path, nullptr, std::chrono::milliseconds(30000), cancel);
  if (fit_mm > 0.0) sp::apply_scale(m, sp::fit_scale(m, fit_mm));
  return m;
}

json JobRequest::to_json() const {
  json j = {{"mesh", mesh}};
  if (fit_mm > 0.0) j["fit_mm"] = fit_mm;
  if (!spec.empty()) j["spec"] = spec;
  if (!settings.empty()) j["settings"] = settings;
  if (!truth.empty()) j["truth"] = truth;
  if (rough_vertices) j["rough_vertices"] = *rough_vertices;
  if (bbox_mm) j["bbox_mm"] = {bbox_mm->x(), bbox_mm->y(), bbox_mm->z()};
  if (!placement.empty()) j["placement"] = placement;
  if (setups) j["setups"] = *setups;
  return j;
}

JobRequest JobRequest::from_json(const json& j) {
  JobRequest r;
  r.mesh = j.value("mesh", std::string());
  if (j.contains("bbox_mm")) {
    const auto v = j["bbox_mm"].get<std::vector<double>>();
    if (v.size() != 3) throw std::invalid_argument("bbox_mm: three sizes (x, y, z mm)");
    r.bbox_mm = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  r.fit_mm = j.value("fit_mm", 0.0);
  r.spec = j.value("spec", std::string());
  r.settings = j.value("settings", std::string());
  r.truth = j.value("truth", std::string());
  if (j.contains("rough_vertices")) r.rough_vertices = j["rough_vertices"].get<std::size_t>();
  r.placement = j.value("placement", std::string());
  if (j.contains("setups")) r.setups = j["setups"].get<int>();
  return r;
}

void validate_request(const JobRequest& r, const std::atomic<int>* cancel) {
  if (!r.mesh.empty() && r.bbox_mm)
    throw std::invalid_argument("submit: 'mesh' and 'bbox_mm' both given; give a rough model or a bounding box to rough-scan, not both");
  if (r.mesh.empty() && !r.bbox_mm) throw std::invalid_argument("submit: give 'mesh' (a rough model) or 'bbox_mm' (start with a rough scan)");
  if (r.bbox_mm && !(r.bbox_mm->minCoeff() > 0.0 && r.bbox_mm->maxCoeff() < 1000.0))
    throw std::invalid_argument("submit: 'bbox_mm' sizes must be in (0, 1000) mm");
  if (!(r.fit_mm >= 0.0) || !std::isfinite(r.fit_mm)) throw std::invalid_argument("submit: 'fit_mm' must be > 0");
  if (r.rough_vertices && (*r.rough_vertices < sp::kMinRoughVertices || *r.rough_vertices > sp::kMaxRoughVertices))
    throw std::invalid_argument("submit: 'rough_vertices' must be in [" + std::to_string(sp::kMinRoughVertices) + ", " +
                                std::to_string(sp::kMaxRoughVertices) + "], got " + std::to_string(*r.rough_vertices));
  if (!r.placement.empty() && r.placement != "auto" && r.placement != "as_given")
    throw std::invalid_argument("submit: 'placement' must be auto or as_given");
  if (r.setups && (*r.setups < 1 || *r.setups > kMaxSetups))
    throw std::invalid_argument("submit: 'setups' must be in [1, " + std::to_string(kMaxSetups) + "], got " + std::to_string(*r.setups));
  if (r.setups && *r.setups > 1 && r.bbox_mm)
    throw std::invalid_argument("submit: 'setups' over 1 needs a mesh; a bounding-box job measures one setup (its rough model "
                                "is fused in the table frame, and turning it over is not supported yet)");
  if (r.bbox_mm && r.placement == "auto")
    throw std::invalid_argument("submit: 'placement' auto needs a mesh; a bounding-box job's object already stands on the table");
  if (!r.mesh.empty()) load_object(r.mesh, r.fit_mm, cancel);
  if (!r.truth.empty()) load_object(r.truth, r.fit_mm, cancel);
  if (!r.spec.empty()) sp::load_spec(r.spec);
  if (!r.settings.empty()) sp::load_planner_settings(r.settings);
}

}  // namespace scancell::daemon
