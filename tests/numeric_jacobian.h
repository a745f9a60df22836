// The one numeric Jacobian of the tests (issue 31; PoseLib's verify_jacobian in spirit): central
// differences of a vector function, each variable stepped by step x max(1, |x_k|), so a focal
// length of ~1e3 px and a distortion coefficient of ~1e-1 are both stepped where O(h²)
// truncation and rounding (~1e-10) are small. Analytic Jacobians, jets and closed forms are
// checked against it.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

namespace raytime {

// d f / d x at x, one column per variable; f maps an Eigen::VectorXd to any Eigen vector.
template <typename Function>
Eigen::MatrixXd NumericJacobian(const Function& f, const Eigen::VectorXd& x, double step) {
  Eigen::MatrixXd jacobian;
  for (Eigen::Index k = 0; k < x.size(); ++k) {
    const double h = step * std::max(1.0, std::abs(x(k)));
    Eigen::VectorXd plus = x, minus = x;
    plus(k) += h;
    minus(k) -= h;
    const Eigen::VectorXd column = (Eigen::VectorXd(f(plus)) - Eigen::VectorXd(f(minus))) / (2 * h);
    if (k == 0) jacobian.resize(column.size(), x.size());
    jacobian.col(k) = column;
  }
  return jacobian;
}

}  // namespace raytime
