// Vectors of random draws in one fixed order. The arguments of one call are evaluated in an
// unspecified order (gcc evaluates the last first, clang the first first), so
// `Eigen::Vector3d(d(rng), d(rng), d(rng))` builds a different scene with each compiler, and a
// threshold set on one compiler's scene fails on the other's. These draw the last coefficient
// first: the order the tests' scenes were built in, and their thresholds set on, with gcc.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace raytime {

template <class Draw>
Eigen::Vector2d DrawVector2(Draw&& draw) {
  const double y = draw();
  const double x = draw();
  return Eigen::Vector2d(x, y);
}

template <class Draw>
Eigen::Vector3d DrawVector3(Draw&& draw) {
  const double z = draw();
  const double y = draw();
  const double x = draw();
  return Eigen::Vector3d(x, y, z);
}

// Coefficients as Eigen::Quaterniond(w, x, y, z) takes them: z drawn first, w last.
template <class Draw>
Eigen::Quaterniond DrawQuaternion(Draw&& draw) {
  const double z = draw();
  const double y = draw();
  const double x = draw();
  const double w = draw();
  return Eigen::Quaterniond(w, x, y, z);
}

}  // namespace raytime
