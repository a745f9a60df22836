// Shared evaluation cache (paper §3.7 "Shared evaluation cache"): a Ceres EvaluationCallback
// that, once per evaluation point, computes every observation's undistorted pixel û and ray
// point X = O + t·D with forward-mode jets over the observation's 16 local parameters
// (intrinsics 8 of its image's intrinsics block, pose 7, ray time 1), TBB-parallel over
// observations. The residuals
// (CachedCrossProjectionCost) then only project and copy the cached derivative blocks into their
// own Jacobians, so the Newton undistortion and the unprojection run once per observation rather
// than once per residual.
#pragma once

#include <ceres/evaluation_callback.h>

#include <vector>

namespace raytime {

// Local parameter slots of an observation's jets.
inline constexpr int kCacheIntrinsicsOffset = 0;  // 8 intrinsics
inline constexpr int kCachePoseOffset = 8;        // 7 pose entries (quaternion xyzw, centre)
inline constexpr int kCacheRayTimeOffset = 15;    // 1 ray time
inline constexpr int kCacheNumLocal = 16;

struct CachedObservation {
  double undistorted[2];               // û
  double d_undistorted[2 * 8];         // dû/d(intrinsics), row-major 2x8
  double point[3];                     // X (observations owning a ray time)
  double d_point[3 * kCacheNumLocal];  // dX/d(local parameters), row-major 3x16
};

class ObservationCache : public ceres::EvaluationCallback {
 public:
  struct Source {
    double pixel[2];    // observed (distorted) pixel
    int image = 0;      // pose block index
    int camera = 0;     // intrinsics block index (its image's camera, refine/solve/camera_blocks.h)
    int ray_time = -1;  // ray-time index, -1 when the observation is only projected into
  };

  // The arrays are the problem's parameter blocks, consecutive per kind (intrinsics blocks of 8,
  // pose blocks of 7, ray times; Ceres writes each evaluation point into them before calling
  // PrepareForEvaluation); they must outlive the cache.
  ObservationCache(const double* intrinsics, const double* poses, const double* ray_times,
                   std::vector<Source> sources, int num_threads);

  // Recomputes values on a new evaluation point, and jets when Jacobians are requested and the
  // cache holds values only (Ceres evaluates a trial point's cost first, then the Jacobian at
  // the same point once the step is accepted).
  void PrepareForEvaluation(bool evaluate_jacobians, bool new_evaluation_point) override;

  const CachedObservation& operator[](int observation) const { return entries_[observation]; }
  int size() const { return static_cast<int>(entries_.size()); }
  // Number of value-only and jet passes, for tests and the benchmark.
  int value_passes() const { return value_passes_; }
  int jet_passes() const { return jet_passes_; }

 private:
  void ComputeValues();
  void ComputeJets();

  const double* intrinsics_;
  const double* poses_;
  const double* ray_times_;
  std::vector<Source> sources_;
  std::vector<CachedObservation> entries_;
  int num_threads_;
  bool have_values_ = false;
  bool have_jets_ = false;
  int value_passes_ = 0;
  int jet_passes_ = 0;
};

}  // namespace raytime
