#include "refine/solve/gauge_polish.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/manifold.h>
#include <ceres/problem.h>
#include <ceres/rotation.h>
#include <ceres/solver.h>

#include <cmath>

#include "refine/solve/ray_geometry.h"

namespace raytime {
namespace {

// The prior terms of one camera after the similarity (R, T, s) is applied to its solved pose:
// sqrt(2λp/N)(sR·O + T - O^prior) and sqrt(2λR/N)·Log((R^prior)^-1 R R_i), as PosePriorCost.
class SimilarityPriorCost {
 public:
  SimilarityPriorCost(const Rigid3& solved, const Rigid3& prior, double position_scale,
                      double orientation_scale)
      : solved_(solved),
        prior_(prior),
        position_scale_(position_scale),
        orientation_scale_(orientation_scale) {}

  static ceres::CostFunction* Create(const Rigid3& solved, const Rigid3& prior,
                                     double position_scale, double orientation_scale) {
    return new ceres::AutoDiffCostFunction<SimilarityPriorCost, 6, 4, 3, 1>(
        new SimilarityPriorCost(solved, prior, position_scale, orientation_scale));
  }

  // rotation: Eigen order (x, y, z, w).
  template <typename T>
  bool operator()(const T* rotation, const T* translation, const T* log_scale, T* residual) const {
    T R[9];
    RotationFromQuaternion(rotation, R);
    const T scale = exp(log_scale[0]);
    const Eigen::Vector3d& o = solved_.translation;
    for (int r = 0; r < 3; ++r) {
      const T moved =
          scale * (R[3 * r] * o[0] + R[3 * r + 1] * o[1] + R[3 * r + 2] * o[2]) + translation[r];
      residual[r] = T(position_scale_) * (moved - T(prior_.translation[r]));
    }
    const T q[4] = {rotation[3], rotation[0], rotation[1], rotation[2]};
    const T qi[4] = {T(solved_.rotation.w()), T(solved_.rotation.x()), T(solved_.rotation.y()),
                     T(solved_.rotation.z())};
    const T prior_inverse[4] = {T(prior_.rotation.w()), T(-prior_.rotation.x()),
                                T(-prior_.rotation.y()), T(-prior_.rotation.z())};
    T rotated[4], relative[4], log[3];
    ceres::QuaternionProduct(q, qi, rotated);  // (w, x, y, z) order
    ceres::QuaternionProduct(prior_inverse, rotated, relative);
    ceres::QuaternionToAngleAxis(relative, log);
    for (int r = 0; r < 3; ++r) residual[3 + r] = T(orientation_scale_) * log[r];
    return true;
  }

 private:
  Rigid3 solved_;
  Rigid3 prior_;
  double position_scale_;
  double orientation_scale_;
};

// The prior terms of E (PosePriorCost) over the movable cameras.
double PriorCost(const std::vector<Rigid3>& prior, const std::vector<bool>& movable,
                 const std::vector<Rigid3>& world_from_cam, double position_weight,
                 double orientation_weight) {
  const double n = static_cast<double>(prior.size());
  double cost = 0.0;
  for (size_t i = 0; i < prior.size(); ++i) {
    if (!movable[i]) continue;
    const double angle = RotationAngle(prior[i].rotation.inverse() * world_from_cam[i].rotation);
    cost +=
        position_weight / n * (world_from_cam[i].translation - prior[i].translation).squaredNorm() +
        orientation_weight / n * angle * angle;
  }
  return cost;
}

}  // namespace

GaugePolishSummary PolishGauge(const std::vector<Rigid3>& prior, const std::vector<bool>& movable,
                               double position_weight, double orientation_weight,
                               double gauge_orientation_weight, std::vector<Rigid3>* world_from_cam,
                               std::vector<double>* ray_times) {
  GaugePolishSummary summary;
  const double n = static_cast<double>(prior.size());
  double rotation[4] = {0.0, 0.0, 0.0, 1.0};
  double translation[3] = {0.0, 0.0, 0.0};
  double log_scale = 0.0;
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::EigenQuaternionManifold quaternion_manifold;
  problem.AddParameterBlock(rotation, 4, &quaternion_manifold);
  int num_movable = 0;
  for (size_t i = 0; i < prior.size(); ++i) {
    if (!movable[i]) continue;
    ++num_movable;
    problem.AddResidualBlock(
        SimilarityPriorCost::Create((*world_from_cam)[i], prior[i],
                                    std::sqrt(2.0 * position_weight / n),
                                    std::sqrt(2.0 * gauge_orientation_weight / n)),
        nullptr, rotation, translation, &log_scale);
  }
  if (num_movable == 0) return summary;
  double fit_cost_before = 0.0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &fit_cost_before, nullptr, nullptr, nullptr);
  summary.prior_cost_before =
      PriorCost(prior, movable, *world_from_cam, position_weight, orientation_weight);

  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = 50;
  options.function_tolerance = 1e-14;
  options.gradient_tolerance = 1e-16;
  options.parameter_tolerance = 1e-14;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary solver_summary;
  ceres::Solve(options, &problem, &solver_summary);
  // Monotone by construction (the identity is the start); keep it only if it helped the fit.
  summary.prior_cost_after = summary.prior_cost_before;
  if (!(solver_summary.final_cost < fit_cost_before)) return summary;

  Sim3 similarity;
  similarity.rotation =
      Eigen::Quaterniond(rotation[3], rotation[0], rotation[1], rotation[2]).normalized();
  similarity.translation = Eigen::Vector3d(translation[0], translation[1], translation[2]);
  similarity.scale = std::exp(log_scale);
  summary.rotation_deg = DegreesFromRadians(RotationAngle(similarity.rotation));
  summary.translation = similarity.translation.norm();
  summary.scale = similarity.scale;
  for (size_t i = 0; i < prior.size(); ++i) {
    if (movable[i]) (*world_from_cam)[i] = similarity.TransformPose((*world_from_cam)[i]);
  }
  for (double& t : *ray_times) t *= similarity.scale;
  summary.prior_cost_after =
      PriorCost(prior, movable, *world_from_cam, position_weight, orientation_weight);
  return summary;
}

}  // namespace raytime
