#include "refine/solve/ray_time_problem.h"

#include <ceres/product_manifold.h>

#include <algorithm>

#include "refine/solve/cross_projection_cost.h"
#include "refine/solve/pose_prior_cost.h"

namespace raytime {
namespace {

// Paper §3.3: focal lengths positive (ray times: kRayTimeLowerBound).
constexpr double kFocalLowerBound = 1e-9;  // pixels

using PoseManifold =
    ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;

ceres::LossFunction* ScaledArctan(double scale_px2, double weight) {
  return new ceres::ScaledLoss(new ceres::ArctanLoss(scale_px2), weight, ceres::TAKE_OWNERSHIP);
}

// The intrinsics a solve holds (all of them without self-calibration).
std::vector<int> HeldIntrinsics(const RayTimeProblemSettings& settings) {
  const bool refined[kNumIntrinsics] = {
      settings.refine_focal,           settings.refine_focal,      settings.refine_principal_point,
      settings.refine_principal_point, settings.refine_distortion, settings.refine_distortion,
      settings.refine_distortion,      settings.refine_distortion};
  std::vector<int> held;
  for (int c = 0; c < kNumIntrinsics; ++c) {
    if (!refined[c]) held.push_back(c);
  }
  return held;
}

}  // namespace

RayTimeProblem::RayTimeProblem(const RefineInput& input, const ProblemLayout& layout,
                               const std::vector<Rigid3>& prior_world_from_cam,
                               const std::vector<Rigid3>& initial_world_from_cam,
                               const CameraBlocks& cameras,
                               const std::vector<double>& initial_ray_times,
                               const RayTimeProblemSettings& settings)
    : intrinsics_info_(cameras.cameras), ray_times_(initial_ray_times) {
  CopyStartingValues(cameras, initial_world_from_cam);
  const std::vector<int> held = HeldIntrinsics(settings);
  // Every intrinsic held: undistorted pixels and rays are constants of the solve, computed once
  // (FixedObservationRays), and the residuals hold them (FixedIntrinsicsCrossProjectionCost); the
  // cache serves self-calibration.
  fixed_intrinsics_residuals_ =
      settings.use_evaluation_cache && held.size() == static_cast<size_t>(kNumIntrinsics);
  if (!fixed_intrinsics_residuals_ && settings.use_evaluation_cache) {
    CreateCache(input, layout, cameras, settings.num_threads);
  }
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.evaluation_callback = cache_.get();
  problem_ = std::make_unique<ceres::Problem>(problem_options);
  AddParameterBlocks(layout, cameras);
  AddMatchTerm(input, layout, cameras, settings.loss_scale_px2);
  AddPriorTerms(prior_world_from_cam, settings);
  HoldIntrinsics(held, settings.refine_focal);
}

void RayTimeProblem::CopyStartingValues(const CameraBlocks& cameras,
                                        const std::vector<Rigid3>& initial_world_from_cam) {
  const int num_blocks = static_cast<int>(cameras.cameras.size());
  intrinsics_.resize(kNumIntrinsics * num_blocks);
  for (int b = 0; b < num_blocks; ++b) {
    std::copy(cameras.cameras[b].params.begin(), cameras.cameras[b].params.end(),
              intrinsics_block(b));
  }
  const int num_cameras = static_cast<int>(initial_world_from_cam.size());
  poses_.resize(kPoseBlockSize * num_cameras);
  for (int i = 0; i < num_cameras; ++i) ToPoseBlock(initial_world_from_cam[i], pose_block(i));
}

void RayTimeProblem::CreateCache(const RefineInput& input, const ProblemLayout& layout,
                                 const CameraBlocks& cameras, int num_threads) {
  std::vector<ObservationCache::Source> sources(layout.observations.size());
  for (size_t o = 0; o < layout.observations.size(); ++o) {
    const LayoutObservation& obs = layout.observations[o];
    sources[o].pixel[0] = input.keypoints[obs.image](obs.keypoint, 0);
    sources[o].pixel[1] = input.keypoints[obs.image](obs.keypoint, 1);
    sources[o].image = obs.image;
    sources[o].camera = cameras.camera_of_image[obs.image];
    sources[o].ray_time = obs.ray_time;
  }
  cache_ = std::make_unique<ObservationCache>(intrinsics_.data(), poses_.data(), ray_times_.data(),
                                              std::move(sources), num_threads);
}

void RayTimeProblem::AddParameterBlocks(const ProblemLayout& layout, const CameraBlocks& cameras) {
  // Only the intrinsics blocks some residual reaches are in the problem: nothing else constrains
  // the others (cameras of images without matches keep their values).
  const int num_blocks = static_cast<int>(cameras.cameras.size());
  intrinsics_used_.assign(num_blocks, false);
  if (!fixed_intrinsics_residuals_) {
    for (const CrossProjection& residual : layout.residuals) {
      intrinsics_used_[cameras.camera_of_image[layout.observations[residual.source].image]] = true;
      intrinsics_used_[cameras.camera_of_image[layout.observations[residual.target].image]] = true;
    }
  }
  pose_manifold_ = std::make_unique<PoseManifold>();
  for (int b = 0; b < num_blocks; ++b) {
    if (intrinsics_used_[b]) problem_->AddParameterBlock(intrinsics_block(b), kNumIntrinsics);
  }
  const int num_cameras = static_cast<int>(poses_.size()) / kPoseBlockSize;
  for (int i = 0; i < num_cameras; ++i) {
    problem_->AddParameterBlock(pose_block(i), kPoseBlockSize, pose_manifold_.get());
  }
  for (size_t t = 0; t < ray_times_.size(); ++t) {
    problem_->AddParameterBlock(ray_time_block(static_cast<int>(t)), 1);
    problem_->SetParameterLowerBound(ray_time_block(static_cast<int>(t)), 0, kRayTimeLowerBound);
  }
}

// Match term: 1/S Σ ρ(|r|²) with S scalar components (see the header), one cost variant per
// residual by its intrinsics blocks (refine/solve/cross_projection_cost.h).
void RayTimeProblem::AddMatchTerm(const RefineInput& input, const ProblemLayout& layout,
                                  const CameraBlocks& cameras, double loss_scale_px2) {
  const int num_scalar_residuals = 2 * static_cast<int>(layout.residuals.size());
  match_loss_weight_ = num_scalar_residuals > 0 ? 2.0 / num_scalar_residuals : 0.0;
  match_loss_ = std::make_unique<ceres::LossFunctionWrapper>(
      ScaledArctan(loss_scale_px2, match_loss_weight_), ceres::TAKE_OWNERSHIP);
  camera_observed_ = ObservedImages(layout, static_cast<int>(poses_.size()) / kPoseBlockSize);
  const ObservationRays fixed = fixed_intrinsics_residuals_
                                    ? FixedObservationRays(input, layout, cameras)
                                    : ObservationRays();
  match_blocks_.reserve(layout.residuals.size());
  for (const CrossProjection& residual : layout.residuals) {
    const LayoutObservation& source = layout.observations[residual.source];
    const LayoutObservation& target = layout.observations[residual.target];
    const int source_camera = cameras.camera_of_image[source.image];
    const int target_camera = cameras.camera_of_image[target.image];
    const Eigen::Vector2d source_pixel =
        input.keypoints[source.image].row(source.keypoint).transpose();
    const Eigen::Vector2d target_pixel =
        input.keypoints[target.image].row(target.keypoint).transpose();
    if (fixed_intrinsics_residuals_) {
      match_blocks_.push_back(problem_->AddResidualBlock(
          FixedIntrinsicsCrossProjectionCost::Create(fixed.rays[residual.source],
                                                     fixed.undistorted[residual.target],
                                                     intrinsics_block(target_camera)),
          match_loss_.get(), pose_block(source.image), ray_time_block(source.ray_time),
          pose_block(target.image)));
    } else if (source_camera == target_camera) {
      // One block (Ceres refuses a residual holding a block twice).
      ceres::CostFunction* cost =
          cache_ ? CachedCrossProjectionCost::Create(cache_.get(), residual.source, residual.target)
                 : CrossProjectionAutoDiffCost::Create(source_pixel, target_pixel);
      match_blocks_.push_back(problem_->AddResidualBlock(
          cost, match_loss_.get(), intrinsics_block(source_camera), pose_block(source.image),
          ray_time_block(source.ray_time), pose_block(target.image)));
    } else {
      ceres::CostFunction* cost =
          cache_ ? CachedTwoCameraCrossProjectionCost::Create(cache_.get(), residual.source,
                                                              residual.target)
                 : TwoCameraCrossProjectionAutoDiffCost::Create(source_pixel, target_pixel);
      match_blocks_.push_back(
          problem_->AddResidualBlock(cost, match_loss_.get(), intrinsics_block(source_camera),
                                     pose_block(source.image), ray_time_block(source.ray_time),
                                     intrinsics_block(target_camera), pose_block(target.image)));
    }
  }
}

// Prior terms λp/N, λR/N (§3.3). A camera no match reaches is held at its start: its only term is
// the prior, whose minimum is the anchor.
void RayTimeProblem::AddPriorTerms(const std::vector<Rigid3>& prior_world_from_cam,
                                   const RayTimeProblemSettings& settings) {
  const int num_cameras = static_cast<int>(poses_.size()) / kPoseBlockSize;
  const double position_weight = settings.position_weight / num_cameras;
  const double orientation_weight = settings.orientation_weight / num_cameras;
  for (int i = 0; i < num_cameras; ++i) {
    prior_blocks_.push_back(problem_->AddResidualBlock(
        PosePriorCost::Create(prior_world_from_cam[i], position_weight, orientation_weight),
        nullptr, pose_block(i)));
    if (!camera_observed_[i]) problem_->SetParameterBlockConstant(pose_block(i));
  }
}

// Self-calibration (§3.1): the intrinsics blocks are constant unless some intrinsics are refined;
// the others are held by a subset manifold (one, shared by the blocks).
void RayTimeProblem::HoldIntrinsics(const std::vector<int>& held, bool refine_focal) {
  if (held.size() < kNumIntrinsics && !held.empty()) {
    intrinsics_manifold_ = std::make_unique<ceres::SubsetManifold>(kNumIntrinsics, held);
  }
  for (size_t b = 0; b < intrinsics_used_.size(); ++b) {
    if (!intrinsics_used_[b]) continue;
    double* block = intrinsics_block(static_cast<int>(b));
    if (held.size() == kNumIntrinsics) {
      problem_->SetParameterBlockConstant(block);
      continue;
    }
    if (intrinsics_manifold_) problem_->SetManifold(block, intrinsics_manifold_.get());
    if (refine_focal) {
      problem_->SetParameterLowerBound(block, kFx, kFocalLowerBound);
      problem_->SetParameterLowerBound(block, kFy, kFocalLowerBound);
    }
  }
}

RayTimeProblem::~RayTimeProblem() = default;

void RayTimeProblem::SetLossScale(double scale_px2) {
  match_loss_->Reset(ScaledArctan(scale_px2, match_loss_weight_), ceres::TAKE_OWNERSHIP);
}

std::vector<Rigid3> RayTimeProblem::WorldFromCam() const {
  const int num_cameras = static_cast<int>(poses_.size()) / kPoseBlockSize;
  std::vector<Rigid3> poses(num_cameras);
  for (int i = 0; i < num_cameras; ++i) {
    poses[i] = FromPoseBlock(poses_.data() + kPoseBlockSize * i);
  }
  return poses;
}

std::vector<CameraIntrinsics> RayTimeProblem::Intrinsics() const {
  std::vector<CameraIntrinsics> cameras = intrinsics_info_;
  for (size_t b = 0; b < cameras.size(); ++b) {
    std::copy_n(intrinsics_.begin() + kNumIntrinsics * b, kNumIntrinsics,
                cameras[b].params.begin());
  }
  return cameras;
}

}  // namespace raytime
