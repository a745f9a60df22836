// The Ceres problem of paper §3.2–3.4 and §3.7, built once from a layout: parameter blocks
// (intrinsics 8 per intrinsics block some residual reaches: one for shared intrinsics, one per
// camera for per-image intrinsics, refine/solve/camera_blocks.h, none when every intrinsic is held;
// one 7-vector pose per image on the quaternion × R³ manifold; one ray time per layout ray time
// bounded below at 1e-9), the cross-projection residuals (the fixed-intrinsics variant when no
// intrinsic is refined, else the one- or two-block variant by the images' blocks,
// cross_projection_cost.h) under one shared arctan loss whose scale GNC changes between stages
// without rebuilding, and the pose priors.
//
// Loss normalization: Ceres minimizes ½ Σ ρ_b(|f_b|²). The match residuals carry
// ScaledLoss(ArctanLoss(a), 2/S) with S = 2 × (number of 2-vector residuals) the count of scalar
// residual components (S = 4M for the per-observation layout), and the prior residuals are
// scaled by sqrt(2λ/N); Ceres' cost is then exactly E of paper eq. (energy), which the tests
// check term by term. The anchored layout has one residual per non-anchor observation, and the
// same rule normalizes it by its own scalar count.
#pragma once

#include <ceres/loss_function.h>
#include <ceres/manifold.h>
#include <ceres/problem.h>

#include <memory>
#include <vector>

#include "refine/solve/camera_blocks.h"
#include "refine/solve/evaluation_cache.h"
#include "refine/solve/problem_layout.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {

struct RayTimeProblemSettings {
  double position_weight = 1e-2;    // λp
  double orientation_weight = 1e3;  // λR
  double loss_scale_px2 = 100.0;    // initial arctan scale
  bool refine_focal = false;
  bool refine_principal_point = false;
  bool refine_distortion = false;
  bool use_evaluation_cache = true;
  int num_threads = 1;  // cache threads
};

class RayTimeProblem {
 public:
  // `prior_world_from_cam` anchors the prior terms; the solve starts at
  // `initial_world_from_cam`, the intrinsics of `cameras` (its blocks, and which image uses
  // which) and `initial_ray_times` (one per layout ray time). `input` and `layout` must outlive
  // the problem.
  RayTimeProblem(const RefineInput& input, const ProblemLayout& layout,
                 const std::vector<Rigid3>& prior_world_from_cam,
                 const std::vector<Rigid3>& initial_world_from_cam, const CameraBlocks& cameras,
                 const std::vector<double>& initial_ray_times,
                 const RayTimeProblemSettings& settings);
  ~RayTimeProblem();
  RayTimeProblem(const RayTimeProblem&) = delete;
  RayTimeProblem& operator=(const RayTimeProblem&) = delete;

  // Replaces the arctan scale a of every match residual (GNC stage change, §3.5).
  void SetLossScale(double scale_px2);

  ceres::Problem& problem() { return *problem_; }
  std::vector<Rigid3> WorldFromCam() const;
  // One per block of the `cameras` given: the solved intrinsics (the initial ones of a block no
  // residual reaches).
  std::vector<CameraIntrinsics> Intrinsics() const;
  const std::vector<double>& ray_times() const { return ray_times_; }
  // Null when the cache is off or not needed (fixed_intrinsics_residuals()).
  ObservationCache* cache() { return cache_.get(); }
  // Parameter blocks, for tests.
  double* intrinsics_block(int camera) { return intrinsics_.data() + kNumIntrinsics * camera; }
  double* pose_block(int image) { return poses_.data() + kPoseBlockSize * image; }
  double* ray_time_block(int ray_time) { return ray_times_.data() + ray_time; }
  // The cross-projection residual blocks in layout order, and the prior blocks per camera.
  const std::vector<ceres::ResidualBlockId>& match_blocks() const { return match_blocks_; }
  const std::vector<ceres::ResidualBlockId>& prior_blocks() const { return prior_blocks_; }
  // 2/S, the ScaledLoss factor of the match term (see the file comment).
  double match_loss_weight() const { return match_loss_weight_; }
  // Per image: whether some residual reaches it (the others are held constant).
  const std::vector<bool>& camera_observed() const { return camera_observed_; }
  // Per intrinsics block: whether some residual reaches it (only those are in the problem; none
  // with fixed-intrinsics residuals).
  const std::vector<bool>& intrinsics_used() const { return intrinsics_used_; }
  // Whether the match residuals are FixedIntrinsicsCrossProjectionCost (every intrinsic held and
  // the cache on): blocks source pose, ray time, target pose; no cache.
  bool fixed_intrinsics_residuals() const { return fixed_intrinsics_residuals_; }

 private:
  // The constructor's steps, in order.
  void CopyStartingValues(const CameraBlocks& cameras,
                          const std::vector<Rigid3>& initial_world_from_cam);
  void CreateCache(const RefineInput& input, const ProblemLayout& layout,
                   const CameraBlocks& cameras, int num_threads);
  void AddParameterBlocks(const ProblemLayout& layout, const CameraBlocks& cameras);
  void AddMatchTerm(const RefineInput& input, const ProblemLayout& layout,
                    const CameraBlocks& cameras, double loss_scale_px2);
  void AddPriorTerms(const std::vector<Rigid3>& prior_world_from_cam,
                     const RayTimeProblemSettings& settings);
  void HoldIntrinsics(const std::vector<int>& held, bool refine_focal);

  std::vector<CameraIntrinsics> intrinsics_info_;
  std::vector<double> intrinsics_;  // kNumIntrinsics per block
  std::vector<double> poses_;
  std::vector<double> ray_times_;
  std::vector<bool> camera_observed_;
  std::vector<bool> intrinsics_used_;
  bool fixed_intrinsics_residuals_ = false;
  std::unique_ptr<ObservationCache> cache_;
  std::unique_ptr<ceres::Manifold> pose_manifold_;
  std::unique_ptr<ceres::Manifold> intrinsics_manifold_;
  double match_loss_weight_ = 0.0;
  std::unique_ptr<ceres::LossFunctionWrapper> match_loss_;
  std::vector<ceres::ResidualBlockId> match_blocks_;
  std::vector<ceres::ResidualBlockId> prior_blocks_;
  // Declared last: destroyed first, before the cache, loss and manifolds it points to.
  std::unique_ptr<ceres::Problem> problem_;
};

}  // namespace raytime
