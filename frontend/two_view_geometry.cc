#include "frontend/two_view_geometry.h"

#include <cmath>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.h"
#include "core/geometry.h"
#include "core/options.h"

namespace raytime {
namespace {

// Both estimators need more than the minimal 5 (E) or 7 (F) samples to say anything.
constexpr int kMinCorrespondences = 8;

cv::Mat ToCv(const PointList& points) {
  cv::Mat out(static_cast<int>(points.rows()), 2, CV_64F);
  for (int k = 0; k < out.rows; ++k) {
    out.at<double>(k, 0) = points(k, 0);
    out.at<double>(k, 1) = points(k, 1);
  }
  return out;
}

PointList Normalize(const PointList& points, const Eigen::Matrix3d& K) {
  PointList out(points.rows(), 2);
  out.col(0) = (points.col(0).array() - K(0, 2)) / K(0, 0);
  out.col(1) = (points.col(1).array() - K(1, 2)) / K(1, 1);
  return out;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// Signed Sampson residuals of E = [t]x R on the correspondences `rows` (normalized units).
Eigen::VectorXd SampsonResiduals(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                 const PointList& n1, const PointList& n2,
                                 const std::vector<int>& rows) {
  // The per-match loop is scalar code on the matrix's entries (DEVELOPERS.md: Eigen fixed-size
  // expressions per match ran 40x slower in the sanitizer build).
  const Eigen::Matrix3d E_matrix = Skew(t) * R;
  double E[3][3];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) E[i][j] = E_matrix(i, j);
  }
  Eigen::VectorXd r(rows.size());
  for (size_t k = 0; k < rows.size(); ++k) {
    const double a[3] = {n1(rows[k], 0), n1(rows[k], 1), 1.0};
    const double b[3] = {n2(rows[k], 0), n2(rows[k], 1), 1.0};
    double Ea[3], Etb[3];
    for (int i = 0; i < 3; ++i) {
      Ea[i] = E[i][0] * a[0] + E[i][1] * a[1] + E[i][2] * a[2];
      Etb[i] = E[0][i] * b[0] + E[1][i] * b[1] + E[2][i] * b[2];
    }
    const double denominator = Ea[0] * Ea[0] + Ea[1] * Ea[1] + Etb[0] * Etb[0] + Etb[1] * Etb[1];
    const double numerator = b[0] * Ea[0] + b[1] * Ea[1] + b[2] * Ea[2];
    r(k) = denominator > 0 ? numerator / std::sqrt(denominator) : 0.0;
  }
  return r;
}

// Applies a 5-vector update: rotation by exp(delta[0..2]) on the left, translation moved along
// two directions orthogonal to it and renormalized (|t| is not observable).
void Update(const Eigen::Matrix<double, 5, 1>& delta, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
  Eigen::Vector3d u = t->unitOrthogonal();
  const Eigen::Vector3d v = t->cross(u);
  *R = ExpSO3(delta.head<3>()) * *R;
  *t = (*t + delta(3) * u + delta(4) * v).normalized();
}

// The minimal-sample models RANSAC returns put relative rotations tenths of a degree off even
// with thousands of inliers; Levenberg-Marquardt on the Sampson residuals of the inliers (Cauchy
// weights at `scale`, iteratively reweighted) brings them to the accuracy the inliers support.
// Forward-difference Jacobian: 5 parameters, a few thousand residuals.
void RefineRelativePose(const PointList& n1, const PointList& n2, const std::vector<int>& rows,
                        double scale, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
  constexpr int kMaxIterations = 20;
  constexpr double kStep = 1e-7;
  const auto robust_cost = [&](const Eigen::VectorXd& r) {
    return (r.array() / scale).square().log1p().sum();
  };
  Eigen::VectorXd r = SampsonResiduals(*R, *t, n1, n2, rows);
  double cost = robust_cost(r);
  double lambda = 1e-3;
  Eigen::MatrixXd J(rows.size(), 5);
  for (int iteration = 0; iteration < kMaxIterations; ++iteration) {
    for (int d = 0; d < 5; ++d) {
      Eigen::Matrix<double, 5, 1> delta = Eigen::Matrix<double, 5, 1>::Zero();
      delta(d) = kStep;
      Eigen::Matrix3d R_d = *R;
      Eigen::Vector3d t_d = *t;
      Update(delta, &R_d, &t_d);
      J.col(d) = (SampsonResiduals(R_d, t_d, n1, n2, rows) - r) / kStep;
    }
    const Eigen::ArrayXd w = 1.0 / (1.0 + (r.array() / scale).square());
    const Eigen::Matrix<double, 5, 5> H = J.transpose() * w.matrix().asDiagonal() * J;
    const Eigen::Matrix<double, 5, 1> g = J.transpose() * (w * r.array()).matrix();
    bool improved = false;
    while (lambda < 1e8) {
      Eigen::Matrix<double, 5, 5> damped = H;
      damped.diagonal() *= 1.0 + lambda;
      const Eigen::Matrix<double, 5, 1> delta = damped.ldlt().solve(-g);
      Eigen::Matrix3d R_new = *R;
      Eigen::Vector3d t_new = *t;
      Update(delta, &R_new, &t_new);
      const Eigen::VectorXd r_new = SampsonResiduals(R_new, t_new, n1, n2, rows);
      const double cost_new = robust_cost(r_new);
      if (cost_new < cost) {
        const bool converged = cost - cost_new < 1e-10 * cost || delta.norm() < 1e-12;
        *R = R_new;
        *t = t_new;
        r = r_new;
        cost = cost_new;
        lambda = std::max(1e-9, lambda / 10);
        improved = !converged;
        break;
      }
      lambda *= 10;
    }
    if (!improved) break;
  }
}

std::vector<int> MaskIndices(const cv::Mat& mask) {
  std::vector<int> indices;
  for (int k = 0; k < mask.rows * mask.cols; ++k) {
    if (mask.ptr<uint8_t>()[k]) indices.push_back(k);
  }
  return indices;
}

}  // namespace

RobustEstimator ParseRobustEstimator(const std::string& name, const std::string& what) {
  if (name == "magsac") return RobustEstimator::kMagsac;
  if (name == "ransac") return RobustEstimator::kRansac;
  throw InputError(UnknownKeyMessage(what, name, {"magsac", "ransac"}, "estimator"));
}

namespace {

// The rows `indices` of an N x 2 point matrix.
cv::Mat InlierRows(const cv::Mat& points, const std::vector<int>& indices) {
  cv::Mat rows(static_cast<int>(indices.size()), 2, CV_64F);
  for (int k = 0; k < rows.rows; ++k) points.row(indices[k]).copyTo(rows.row(k));
  return rows;
}

// The calibrated case: five-point RANSAC/MAGSAC on normalized points, the pose recovered from its
// inliers, polished, then the inliers of the polished model at max_error_px.
GeometryEstimate CalibratedGeometry(const PointList& x1, const PointList& x2,
                                    const Eigen::Matrix3d& K1, const Eigen::Matrix3d& K2,
                                    RobustEstimator estimator, double ransac_error_px,
                                    double max_error_px, double confidence, int max_iterations) {
  GeometryEstimate result;
  cv::Mat mask;
  const PointList n1 = Normalize(x1, K1), n2 = Normalize(x2, K2);
  const cv::Mat p1 = ToCv(n1), p2 = ToCv(n2);
  const double focal = 0.25 * (K1(0, 0) + K1(1, 1) + K2(0, 0) + K2(1, 1));
  const int method = estimator == RobustEstimator::kMagsac ? static_cast<int>(cv::USAC_MAGSAC)
                                                           : static_cast<int>(cv::RANSAC);
  const cv::Mat identity = cv::Mat::eye(3, 3, CV_64F);
  cv::Mat E = cv::findEssentialMat(p1, p2, identity, method, confidence, ransac_error_px / focal,
                                   max_iterations, mask);
  // The five-point solver may return up to 10 stacked solutions when it cannot choose; a failed
  // estimation returns none.
  if (E.rows < 3 || E.cols != 3 || mask.empty()) return result;
  E = E.rowRange(0, 3).clone();
  result.inliers = MaskIndices(mask);
  if (static_cast<int>(result.inliers.size()) < kMinCorrespondences) {
    result.inliers.clear();
    return result;
  }
  cv::Mat R, t;
  cv::recoverPose(E, InlierRows(p1, result.inliers), InlierRows(p2, result.inliers), identity, R,
                  t);
  Eigen::Matrix3d R_eigen;
  Eigen::Vector3d t_eigen;
  cv::cv2eigen(R, R_eigen);
  cv::cv2eigen(t, t_eigen);
  t_eigen.normalize();
  // Polish on the robust inliers, then take the inliers of the polished model at max_error_px
  // (Sampson distance in normalized units times the focal length is pixels).
  RefineRelativePose(n1, n2, result.inliers, ransac_error_px / focal, &R_eigen, &t_eigen);
  std::vector<int> all(n1.rows());
  std::iota(all.begin(), all.end(), 0);
  const Eigen::VectorXd residuals = SampsonResiduals(R_eigen, t_eigen, n1, n2, all);
  result.inliers.clear();
  for (int k = 0; k < residuals.size(); ++k) {
    if (std::abs(residuals(k)) * focal < max_error_px) result.inliers.push_back(k);
  }
  if (static_cast<int>(result.inliers.size()) < kMinCorrespondences) {
    result.inliers.clear();
    return result;
  }
  TwoViewGeometry& g = result.geometry;
  g.config = TwoViewConfig::kCalibrated;
  g.E = Skew(t_eigen) * R_eigen;
  g.F = K2.inverse().transpose() * g.E * K1.inverse();
  g.cam2_from_cam1 = Rigid3(Eigen::Quaterniond(R_eigen).normalized(), t_eigen);
  return result;
}

// The uncalibrated case: a fundamental matrix by RANSAC/MAGSAC, polished by the normalized
// eight-point fit to its inliers (least squares); whichever of the two models has more inliers at
// max_error_px is kept.
GeometryEstimate UncalibratedGeometry(const PointList& x1, const PointList& x2,
                                      RobustEstimator estimator, double ransac_error_px,
                                      double max_error_px, double confidence, int max_iterations) {
  GeometryEstimate result;
  cv::Mat mask;
  const int method = estimator == RobustEstimator::kMagsac ? static_cast<int>(cv::USAC_MAGSAC)
                                                           : static_cast<int>(cv::FM_RANSAC);
  const cv::Mat F = cv::findFundamentalMat(ToCv(x1), ToCv(x2), method, ransac_error_px, confidence,
                                           max_iterations, mask);
  if (F.rows != 3 || F.cols != 3 || mask.empty()) return result;
  result.inliers = MaskIndices(mask);
  if (static_cast<int>(result.inliers.size()) < kMinCorrespondences) {
    result.inliers.clear();
    return result;
  }
  Eigen::Matrix3d F_eigen;
  cv::cv2eigen(F, F_eigen);
  const auto inliers_of = [&](const Eigen::Matrix3d& candidate) {
    const Eigen::VectorXd distances = SampsonDistances(candidate, x1, x2);
    std::vector<int> inliers;
    for (int k = 0; k < distances.size(); ++k) {
      if (distances(k) < max_error_px) inliers.push_back(k);
    }
    return inliers;
  };
  const cv::Mat F_fit = cv::findFundamentalMat(InlierRows(ToCv(x1), result.inliers),
                                               InlierRows(ToCv(x2), result.inliers), cv::FM_8POINT);
  result.inliers = inliers_of(F_eigen);
  if (F_fit.rows == 3 && F_fit.cols == 3) {
    Eigen::Matrix3d candidate;
    cv::cv2eigen(F_fit, candidate);
    std::vector<int> inliers = inliers_of(candidate);
    if (inliers.size() >= result.inliers.size()) {
      F_eigen = candidate;
      result.inliers = std::move(inliers);
    }
  }
  if (static_cast<int>(result.inliers.size()) < kMinCorrespondences) {
    result.inliers.clear();
    return result;
  }
  result.geometry.config = TwoViewConfig::kUncalibrated;
  result.geometry.F = F_eigen;
  return result;
}

}  // namespace

GeometryEstimate EstimateTwoViewGeometry(const PointList& x1, const PointList& x2,
                                         const Eigen::Matrix3d* K1, const Eigen::Matrix3d* K2,
                                         RobustEstimator estimator, double ransac_error_px,
                                         double max_error_px, double confidence,
                                         int max_iterations) {
  if (x1.rows() != x2.rows()) {
    throw std::invalid_argument("EstimateTwoViewGeometry: point counts differ");
  }
  if (x1.rows() < kMinCorrespondences) return GeometryEstimate();
  if (K1 != nullptr && K2 != nullptr) {
    return CalibratedGeometry(x1, x2, *K1, *K2, estimator, ransac_error_px, max_error_px,
                              confidence, max_iterations);
  }
  return UncalibratedGeometry(x1, x2, estimator, ransac_error_px, max_error_px, confidence,
                              max_iterations);
}

Eigen::VectorXd SampsonDistances(const Eigen::Matrix3d& F, const PointList& x1,
                                 const PointList& x2) {
  Eigen::VectorXd out(x1.rows());
  for (Eigen::Index k = 0; k < x1.rows(); ++k) {
    const Eigen::Vector3d a(x1(k, 0), x1(k, 1), 1.0), b(x2(k, 0), x2(k, 1), 1.0);
    const Eigen::Vector3d Fa = F * a, Ftb = F.transpose() * b;
    const double r = b.dot(Fa);
    const double denominator = Fa.head<2>().squaredNorm() + Ftb.head<2>().squaredNorm();
    out(k) = denominator > 0 ? std::abs(r) / std::sqrt(denominator) : 0.0;
  }
  return out;
}

}  // namespace raytime
