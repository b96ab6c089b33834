#pragma once
// Matrices in JSON as their numbers row by row (keys named *_row_major): written by plans, job records and
// plan info, read back with the element named in the error.
#include <cmath>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "common/errors.hpp"

namespace scancell {

/// A matrix (4×4 pose, 3×3 rotation) as one array of its numbers, row after row.
inline nlohmann::json row_major_json(const Eigen::Ref<const Eigen::MatrixXd>& m) {
  nlohmann::json a = nlohmann::json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < m.cols(); ++c) a.push_back(m(r, c));
  return a;
}

/// The 4×4 pose written by row_major_json; DataError naming `what` unless it is 16 finite numbers.
inline Eigen::Matrix4d matrix4_from_row_major(const nlohmann::json& a, const std::string& what) {
  if (!a.is_array() || a.size() != 16) throw DataError(what + ": needs 16 numbers (row major)");
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      const nlohmann::json& v = a[static_cast<std::size_t>(4 * r + c)];
      if (!v.is_number() || !std::isfinite(v.get<double>()))
        throw DataError(what + "[" + std::to_string(4 * r + c) + "]: must be a finite number");
      m(r, c) = v.get<double>();
    }
  return m;
}

}  // namespace scancell
