#include "refine/solve/ray_time_lm_kernel.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "refine/solve/arctan_loss.h"
#include "refine/solve/fixed_chunks.h"
#include "refine/solve/ray_geometry.h"
#include "refine/solve/reduced_camera_system.h"
#include "refine/solve/similarity_retraction.h"

namespace raytime {
namespace {

PriorLinearization LinearizePrior(const Rigid3& pose, const Rigid3& prior, double rotation_scale,
                                  double centre_scale) {
  PriorLinearization out;
  const Eigen::AngleAxisd log(prior.rotation.conjugate() * pose.rotation);
  const Eigen::Vector3d theta = log.angle() * log.axis();
  const double angle = log.angle();
  // Jr⁻¹(θ) = I + ½[θ]× + c·[θ]×², c = (1 - (θ/2)·cot(θ/2)) / θ² (1/12 at 0).
  const double c =
      angle < 1e-4 ? 1.0 / 12.0 : (1.0 - 0.5 * angle / std::tan(0.5 * angle)) / (angle * angle);
  const Eigen::Matrix3d skew = CrossMatrix(theta);
  const Eigen::Matrix3d jr_inv = Eigen::Matrix3d::Identity() + 0.5 * skew + c * skew * skew;
  out.rotation_residual = rotation_scale * theta;
  out.rotation_jacobian = rotation_scale * jr_inv * pose.rotation.toRotationMatrix().transpose();
  out.centre_residual = centre_scale * (pose.translation - prior.translation);
  out.centre_scale = centre_scale;
  return out;
}

// r = π_t(O_s + t·R_s·d) - û and, when `source` is not null, its Jacobians (2x6 row-major in
// (φ, δO) of each pose, 2x1 in the ray time); R row-major, K = fx, fy, cx, cy. X moves with the
// source pose as dX = δO - [t R_s d]× φ, and p = R_tᵀ(X - O_t) with the target pose as
// dp = R_tᵀ(-δO + [v]× φ) (R ← Exp(φ) R, so Rᵀ ← Rᵀ Exp(-φ)). The value and ∂r/∂X are
// refine/solve/ray_geometry.h's, which every variant of the residual shares.
void CrossProjectionKernel(const double* rs, const double* os, double t, const double* rt,
                           const double* ot, const double* k, const double* d, const double* u,
                           double* r, double* source, double* ray_time, double* target) {
  double dir[3], point[3], v[3], p[3];
  RayPoint(rs, os, t, d, dir, point);
  TargetResidual(rt, ot, k, point, u, v, p, r);
  if (source == nullptr) return;
  const TargetResidualDerivative derivative = DifferentiateTargetResidual(rt, k, p);
  const double off[3] = {t * dir[0], t * dir[1], t * dir[2]};
  for (int a = 0; a < 2; ++a) {
    const double* m = derivative.du_dX[a];  // du_a/dX = du_a/dp · R_tᵀ
    ray_time[a] = m[0] * dir[0] + m[1] * dir[1] + m[2] * dir[2];
    double* js = source + 6 * a;
    double* jt = target + 6 * a;
    js[0] = off[1] * m[2] - off[2] * m[1];  // off × m
    js[1] = off[2] * m[0] - off[0] * m[2];
    js[2] = off[0] * m[1] - off[1] * m[0];
    jt[0] = m[1] * v[2] - m[2] * v[1];  // m × v
    jt[1] = m[2] * v[0] - m[0] * v[2];
    jt[2] = m[0] * v[1] - m[1] * v[0];
    for (int c = 0; c < 3; ++c) {
      js[3 + c] = m[c];
      jt[3 + c] = -m[c];
    }
  }
}

double SquaredResidual(const RayTimeLmProblem& problem, const RayTimeLmPoint& point,
                       const RayTimeLmResidual& r) {
  double e[2];
  CrossProjectionKernel(point.rotation[r.source_image].data(), point.centre[r.source_image].data(),
                        point.ray_times[r.ray_time], point.rotation[r.target_image].data(),
                        point.centre[r.target_image].data(), problem.pinhole[r.target_image].data(),
                        r.source_ray.data(), r.target_undistorted.data(), e, nullptr, nullptr,
                        nullptr);
  return e[0] * e[0] + e[1] * e[1];
}

}  // namespace

void RayTimeLmPoint::UpdateRotations() {
  rotation.resize(world_from_cam.size());
  centre.resize(world_from_cam.size());
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    const Eigen::Matrix3d r = world_from_cam[i].rotation.toRotationMatrix();
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) rotation[i][3 * a + b] = r(a, b);
      centre[i][a] = world_from_cam[i].translation[a];
    }
  }
}

std::vector<PriorLinearization> LinearizePriors(const RayTimeLmProblem& problem,
                                                const std::vector<Rigid3>& world_from_cam) {
  const double rotation_scale = std::sqrt(2.0 * problem.orientation_weight);
  const double centre_scale = std::sqrt(2.0 * problem.position_weight);
  std::vector<PriorLinearization> priors;
  priors.reserve(world_from_cam.size());
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    priors.push_back(LinearizePrior(world_from_cam[i], problem.prior_world_from_cam[i],
                                    rotation_scale, centre_scale));
  }
  return priors;
}

double RayTimeLmCost(const RayTimeLmProblem& problem, const RayTimeLmPoint& point, double scale_px2,
                     int num_threads, const ReducedCameraPattern& pattern) {
  std::vector<double> chunk_sums(kNumFixedChunks, 0.0);
  ForEachFixedChunk(num_threads, [&](int chunk) {
    // The squared norms a block at a time, then their arctans together (SumOfArctans).
    constexpr int kBlock = 256;
    double squared_norms[kBlock];
    double sum = 0.0;
    const int begin = pattern.residual_begin(pattern.chunk_begin(chunk));
    const int end = pattern.residual_begin(pattern.chunk_end(chunk));
    for (int block = begin; block < end; block += kBlock) {
      const int size = std::min(kBlock, end - block);
      for (int k = 0; k < size; ++k) {
        squared_norms[k] = SquaredResidual(problem, point, problem.residuals[block + k]);
      }
      sum += SumOfArctans(squared_norms, size, scale_px2);
    }
    chunk_sums[chunk] = sum;
  });
  double cost = 0.0;
  for (const double sum : chunk_sums) cost += sum;
  // ρ(s) = w·a·atan(s/a) (ScaledArctanLoss), summed.
  cost *= problem.match_loss_weight * scale_px2;
  double prior = 0.0;
  for (const PriorLinearization& p : LinearizePriors(problem, point.world_from_cam)) {
    prior += p.rotation_residual.squaredNorm() + p.centre_residual.squaredNorm();
  }
  return 0.5 * (cost + prior);
}

void RetractPoint(const RayTimeLmPoint& base, const std::vector<int>& variables,
                  const ReducedStep& step, const Eigen::Matrix<double, 7, 1>& similarity,
                  double alpha, RayTimeLmPoint* out) {
  out->world_from_cam = base.world_from_cam;
  const Eigen::Matrix<double, 7, 1> scaled_similarity = alpha * similarity;
  RetractPoses(variables, alpha * step.cameras, scaled_similarity, &out->world_from_cam);
  // A similarity scales every point's ray time by e^λ (X = O + t·R·d ↦ sQX + T).
  const double log_scale = scaled_similarity[3];
  const double scale = std::exp(log_scale);
  out->ray_times.resize(base.ray_times.size());
  for (size_t t = 0; t < base.ray_times.size(); ++t) {
    const double rest = alpha * step.ray_times[t] - log_scale * base.ray_times[t];
    out->ray_times[t] =
        std::max(scale * RetractRayTime(base.ray_times[t], rest), kRayTimeLowerBound);
  }
  out->UpdateRotations();
}

void CrossProjectionJacobian(const Eigen::Matrix3d& source_rotation,
                             const Eigen::Vector3d& source_centre, double ray_time,
                             const Eigen::Matrix3d& target_rotation,
                             const Eigen::Vector3d& target_centre, const Eigen::Vector4d& pinhole,
                             const Eigen::Vector3d& source_ray,
                             const Eigen::Vector2d& target_undistorted, Eigen::Vector2d* residual,
                             Eigen::Matrix<double, 2, 6>* source_jacobian,
                             Eigen::Vector2d* ray_time_jacobian,
                             Eigen::Matrix<double, 2, 6>* target_jacobian) {
  double rs[9], rt[9];
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      rs[3 * a + b] = source_rotation(a, b);
      rt[3 * a + b] = target_rotation(a, b);
    }
  }
  double r[2], source[12], ray[2], target[12];
  CrossProjectionKernel(rs, source_centre.data(), ray_time, rt, target_centre.data(),
                        pinhole.data(), source_ray.data(), target_undistorted.data(), r, source,
                        ray, target);
  *residual << r[0], r[1];
  *ray_time_jacobian << ray[0], ray[1];
  for (int a = 0; a < 2; ++a) {
    for (int c = 0; c < 6; ++c) {
      (*source_jacobian)(a, c) = source[6 * a + c];
      (*target_jacobian)(a, c) = target[6 * a + c];
    }
  }
}

void PosePriorJacobian(const Rigid3& world_from_cam, const Rigid3& prior_world_from_cam,
                       double rotation_scale, double centre_scale,
                       Eigen::Matrix<double, 6, 1>* residual,
                       Eigen::Matrix<double, 6, 6>* jacobian) {
  const PriorLinearization p =
      LinearizePrior(world_from_cam, prior_world_from_cam, rotation_scale, centre_scale);
  residual->head<3>() = p.centre_residual;
  residual->tail<3>() = p.rotation_residual;
  jacobian->setZero();
  jacobian->block<3, 3>(0, 3) = p.centre_scale * Eigen::Matrix3d::Identity();
  jacobian->block<3, 3>(3, 0) = p.rotation_jacobian;
}

}  // namespace raytime
