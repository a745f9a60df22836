#include "refine/solve/track_adjustment.h"

#include <ceres/iteration_callback.h>
#include <ceres/loss_function.h>
#include <ceres/manifold.h>
#include <ceres/ordered_groups.h>
#include <ceres/problem.h>
#include <ceres/product_manifold.h>
#include <ceres/sized_cost_function.h>
#include <ceres/solver.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include <Eigen/Cholesky>

#include "core/interrupt.h"
#include "refine/solve/pose_prior_cost.h"
#include "refine/solve/ray_geometry.h"
#include "refine/solve/similarity_retraction.h"

namespace raytime {
namespace {

constexpr int kMaxDenseCameras = 200;

using PoseManifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;

// r = π(Rᵀ(X − O)) − û at a rotation R (row-major, camera to world), centre O and point X, with
// its Jacobians in the pose's local parameters (φ, δO), R ← Exp(φ)·R and O ← O + δO, and in X:
// ∂r/∂X from DifferentiateTargetResidual, ∂r/∂O = −∂r/∂X, and R ← Exp(φ)·R turns Rᵀ(X − O) into
// Rᵀ(X − O + (X − O) × φ) to first order. The one linearization of the Ceres cost below and of
// TrackResidualJacobians (the uncertainty's).
struct ReprojectionLinearization {
  Eigen::Vector2d residual;
  Eigen::Matrix<double, 2, 6> pose;
  Eigen::Matrix<double, 2, 3> point;
};

ReprojectionLinearization LinearizeReprojection(const double* R, const double* centre,
                                                const double* pinhole, const double* point,
                                                const double* pixel) {
  ReprojectionLinearization lin;
  double offset[3], p_cam[3];
  TargetResidual(R, centre, pinhole, point, pixel, offset, p_cam, lin.residual.data());
  const TargetResidualDerivative d = DifferentiateTargetResidual(R, pinhole, p_cam);
  lin.point = Eigen::Map<const Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>(&d.du_dX[0][0]);
  lin.pose.leftCols<3>() =
      lin.point * CrossMatrix(Eigen::Vector3d(offset[0], offset[1], offset[2]));
  lin.pose.rightCols<3>() = -lin.point;
  return lin;
}

// The residual above for a pose block (quaternion, centre) and a point block, with closed-form
// Jacobians (automatic differentiation was two thirds of the adjustment's time): the rotation's
// through the quaternion manifold's tangent (a left increment δ turns R into Exp(2δ)·R), written
// in the ambient quaternion as 2·(∂r/∂φ)·Pᵀ, P the manifold's PlusJacobian (orthonormal columns),
// so that Ceres' product with P gives the tangent's Jacobian exactly.
class ReprojectionCost : public ceres::SizedCostFunction<2, kPoseBlockSize, 3> {
 public:
  ReprojectionCost(const Eigen::Vector4d& pinhole, const Eigen::Vector2d& pixel)
      : pinhole_(pinhole), pixel_(pixel) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* pose = parameters[0];
    const double* point = parameters[1];
    double R[9];
    RotationFromQuaternion(pose, R);
    if (jacobians == nullptr) {
      double offset[3], p_cam[3];
      TargetResidual(R, pose + kPoseCentreOffset, pinhole_.data(), point, pixel_.data(), offset,
                     p_cam, residuals);
      return true;
    }
    const ReprojectionLinearization lin =
        LinearizeReprojection(R, pose + kPoseCentreOffset, pinhole_.data(), point, pixel_.data());
    residuals[0] = lin.residual[0];
    residuals[1] = lin.residual[1];
    if (jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, kPoseBlockSize, Eigen::RowMajor>> J(jacobians[0]);
      Eigen::Matrix<double, 4, 3, Eigen::RowMajor> P;
      ceres::EigenQuaternionManifold().PlusJacobian(pose, P.data());
      J.leftCols<4>() = 2.0 * lin.pose.leftCols<3>() * P.transpose();
      J.rightCols<3>() = lin.pose.rightCols<3>();
    }
    if (jacobians[1] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[1]);
      J = lin.point;
    }
    return true;
  }

 private:
  Eigen::Vector4d pinhole_;
  Eigen::Vector2d pixel_;
};

// Ceres' solve aborted when the user stops the run (core/interrupt.h), as the GNC stages are.
class StopCallback : public ceres::IterationCallback {
 public:
  ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
    return StopWasRequested() ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
  }
};

std::vector<double> PoseBlocks(const std::vector<Rigid3>& poses) {
  std::vector<double> blocks(kPoseBlockSize * poses.size());
  for (size_t i = 0; i < poses.size(); ++i)
    ToPoseBlock(poses[i], blocks.data() + kPoseBlockSize * i);
  return blocks;
}

using ScaleHoldingManifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::SubsetManifold>;

struct GaugeCameras {
  int fixed = -1;  // held whole
  int scale = -1;  // one centre coordinate held
  int scale_axis = 0;
};

GaugeCameras ChooseGauge(const TrackAdjustmentProblem& problem) {
  std::vector<int> count(problem.world_from_cam.size(), 0);
  for (const int image : problem.observation_image) ++count[image];
  GaugeCameras gauge;
  const auto most = std::max_element(count.begin(), count.end());
  if (most == count.end() || *most == 0) return gauge;
  gauge.fixed = static_cast<int>(most - count.begin());
  double farthest = 0.0;
  for (size_t i = 0; i < count.size(); ++i) {
    if (count[i] == 0) continue;
    const Eigen::Vector3d offset =
        problem.world_from_cam[i].translation - problem.world_from_cam[gauge.fixed].translation;
    if (offset.norm() > farthest) {
      farthest = offset.norm();
      gauge.scale = static_cast<int>(i);
      offset.cwiseAbs().maxCoeff(&gauge.scale_axis);
    }
  }
  return gauge;
}

}  // namespace

TrackAdjustmentSummary AdjustTracks(TrackAdjustmentProblem* problem) {
  const int num_images = static_cast<int>(problem->world_from_cam.size());
  const int num_observations = static_cast<int>(problem->observation_track.size());
  std::vector<double> poses = PoseBlocks(problem->world_from_cam);
  std::vector<double> points(3 * problem->points.size());
  for (size_t k = 0; k < problem->points.size(); ++k) {
    for (int r = 0; r < 3; ++r) points[3 * k + r] = problem->points[k][r];
  }

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  PoseManifold pose_manifold;
  // 1/S Σ |r|² over S scalar residuals, as the ray-time problem's match term (without its loss:
  // see the header).
  ceres::ScaledLoss loss(nullptr, num_observations > 0 ? 1.0 / num_observations : 0.0,
                         ceres::TAKE_OWNERSHIP);
  std::vector<bool> observed(num_images, false);
  for (int o = 0; o < num_observations; ++o) {
    const int image = problem->observation_image[o];
    observed[image] = true;
    ceres_problem.AddResidualBlock(
        new ReprojectionCost(problem->pinhole[image], problem->observation_pixel[o]), &loss,
        poses.data() + kPoseBlockSize * image, points.data() + 3 * problem->observation_track[o]);
  }
  for (int i = 0; i < num_images; ++i) {
    double* block = poses.data() + kPoseBlockSize * i;
    if (!observed[i]) continue;
    ceres_problem.SetManifold(block, &pose_manifold);
    ceres_problem.AddResidualBlock(
        PosePriorCost::Create(problem->anchor[i], problem->position_weight / num_images,
                              problem->orientation_weight / num_images),
        nullptr, block);
  }
  // The gauge held (see the header): the most observed camera, and the coordinate of the camera
  // farthest from it along which they are farthest apart.
  const GaugeCameras gauge = ChooseGauge(*problem);
  ScaleHoldingManifold scale_manifold(ceres::EigenQuaternionManifold{},
                                      ceres::SubsetManifold(3, {gauge.scale_axis}));
  if (gauge.fixed >= 0)
    ceres_problem.SetParameterBlockConstant(poses.data() + kPoseBlockSize * gauge.fixed);
  if (gauge.scale >= 0) {
    ceres_problem.SetManifold(poses.data() + kPoseBlockSize * gauge.scale, &scale_manifold);
  }

  ceres::Solver::Options options;
  // The points first, then the poses: Ceres' own search for that independent set took about a
  // tenth of the solve.
  options.linear_solver_ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (size_t k = 0; k < problem->points.size(); ++k) {
    options.linear_solver_ordering->AddElementToGroup(points.data() + 3 * k, 0);
  }
  for (int i = 0; i < num_images; ++i) {
    if (observed[i])
      options.linear_solver_ordering->AddElementToGroup(poses.data() + kPoseBlockSize * i, 1);
  }
  // The reduced camera system (6 unknowns per camera) is factorized dense while small, sparse
  // beyond.
  options.linear_solver_type =
      num_images <= kMaxDenseCameras ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
  options.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  options.num_threads = 1;
  options.max_num_iterations = 100;
  // Started at a solution within a few σ of this one (the ray-time solve's): Gauss–Newton steps
  // from the first iteration, where the default radius damped the first few.
  options.initial_trust_region_radius = 1e8;
  // A relative decrease of 1e-7 of the mean squared residual is far below what moves a pose by a
  // fraction of its σ; below it, low-parallax points creep out along their rays with the poses and
  // the cost unchanged (docs/efficiency.md, "The track finish").
  options.function_tolerance = 1e-7;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-10;
  options.logging_type = ceres::SILENT;
  StopCallback stop;
  options.callbacks.push_back(&stop);
  ceres::Solver::Summary solver_summary;
  ceres::Solve(options, &ceres_problem, &solver_summary);

  TrackAdjustmentSummary summary;
  summary.iterations = static_cast<int>(solver_summary.iterations.size()) - 1;
  summary.initial_cost = solver_summary.initial_cost;
  summary.final_cost = solver_summary.final_cost;
  summary.converged = solver_summary.termination_type == ceres::CONVERGENCE;
  summary.message = solver_summary.message;
  for (int i = 0; i < num_images; ++i) {
    problem->world_from_cam[i] = FromPoseBlock(poses.data() + kPoseBlockSize * i);
  }
  for (size_t k = 0; k < problem->points.size(); ++k) {
    problem->points[k] = Eigen::Vector3d(points[3 * k], points[3 * k + 1], points[3 * k + 2]);
  }
  return summary;
}

namespace {

Eigen::Matrix<double, 3, 3, Eigen::RowMajor> RotationOf(const Rigid3& pose) {
  return pose.rotation.normalized().toRotationMatrix();
}

}  // namespace

Eigen::Vector2d TrackResidual(const TrackAdjustmentProblem& problem, int observation) {
  const int image = problem.observation_image[observation];
  const Rigid3& pose = problem.world_from_cam[image];
  const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> R = RotationOf(pose);
  double offset[3], p_cam[3];
  Eigen::Vector2d residual;
  TargetResidual(R.data(), pose.translation.data(), problem.pinhole[image].data(),
                 problem.points[problem.observation_track[observation]].data(),
                 problem.observation_pixel[observation].data(), offset, p_cam, residual.data());
  return residual;
}

Eigen::Vector2d TrackResidualJacobians(const TrackAdjustmentProblem& problem, int observation,
                                       Eigen::Matrix<double, 2, 6>* pose_jacobian,
                                       Eigen::Matrix<double, 2, 3>* point_jacobian) {
  const int image = problem.observation_image[observation];
  const Rigid3& pose = problem.world_from_cam[image];
  const ReprojectionLinearization lin = LinearizeReprojection(
      RotationOf(pose).data(), pose.translation.data(), problem.pinhole[image].data(),
      problem.points[problem.observation_track[observation]].data(),
      problem.observation_pixel[observation].data());
  *pose_jacobian = lin.pose;
  *point_jacobian = lin.point;
  return lin.residual;
}

void AdjustPointsAtFixedPoses(TrackAdjustmentProblem* problem, int iterations) {
  const int n = static_cast<int>(problem->observation_track.size());
  for (int it = 0; it < iterations; ++it) {
    std::vector<Eigen::Matrix3d> H(problem->points.size(), Eigen::Matrix3d::Zero());
    std::vector<Eigen::Vector3d> g(problem->points.size(), Eigen::Vector3d::Zero());
    for (int o = 0; o < n; ++o) {
      Eigen::Matrix<double, 2, 6> pose_jacobian;
      Eigen::Matrix<double, 2, 3> point_jacobian;
      const Eigen::Vector2d residual =
          TrackResidualJacobians(*problem, o, &pose_jacobian, &point_jacobian);
      const int k = problem->observation_track[o];
      H[k] += point_jacobian.transpose() * point_jacobian;
      g[k] += point_jacobian.transpose() * residual;
    }
    for (size_t k = 0; k < problem->points.size(); ++k) {
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(H[k]);
      if (ldlt.info() != Eigen::Success) continue;
      const Eigen::Vector3d step = ldlt.solve(g[k]);
      if (step.allFinite()) problem->points[k] -= step;
    }
  }
}

}  // namespace raytime
