#pragma once
// nanoflann's k-d tree over a vector of points (mm), for the planner's neighbourhood queries: the registration
// cloud's nearest point, and the viewpoints' clearance and local patch.
#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <nanoflann.hpp>

namespace scancell::planner {

/// nanoflann's view of a vector of points. The tree keeps a reference to it: keep both in one object that is
/// neither copied nor moved after the tree is built (or behind a pointer).
struct PointsAdaptor {
  const std::vector<Eigen::Vector3d>* pts;
  std::size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return (*pts)[i][static_cast<Eigen::Index>(d)]; }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};

using PointKdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointsAdaptor>, PointsAdaptor, 3>;

}  // namespace scancell::planner
