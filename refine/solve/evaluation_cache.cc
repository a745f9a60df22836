#include "refine/solve/evaluation_cache.h"

#include <ceres/jet.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <utility>

#include "core/camera.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {
namespace {

using Jet16 = ceres::Jet<double, kCacheNumLocal>;

// Observations per TBB task: large enough to amortize scheduling, small enough to balance.
constexpr int kGrainSize = 256;

template <typename Body>
void ParallelOverObservations(int count, int num_threads, Body&& body) {
  tbb::task_arena arena(num_threads);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, count, kGrainSize),
                      [&](const tbb::blocked_range<int>& range) {
                        for (int o = range.begin(); o != range.end(); ++o) body(o);
                      });
  });
}

}  // namespace

ObservationCache::ObservationCache(const double* intrinsics, const double* poses,
                                   const double* ray_times, std::vector<Source> sources,
                                   int num_threads)
    : intrinsics_(intrinsics),
      poses_(poses),
      ray_times_(ray_times),
      sources_(std::move(sources)),
      entries_(sources_.size()),
      num_threads_(num_threads) {}

void ObservationCache::PrepareForEvaluation(bool evaluate_jacobians, bool new_evaluation_point) {
  if (new_evaluation_point) {
    have_values_ = false;
    have_jets_ = false;
  }
  if (evaluate_jacobians) {
    if (!have_jets_) ComputeJets();
  } else if (!have_values_) {
    ComputeValues();
  }
}

void ObservationCache::ComputeValues() {
  ParallelOverObservations(size(), num_threads_, [this](int o) {
    const Source& source = sources_[o];
    CachedObservation& entry = entries_[o];
    const double* intrinsics = intrinsics_ + kNumIntrinsics * source.camera;
    UndistortPixel(intrinsics, source.pixel, entry.undistorted);
    if (source.ray_time >= 0) {
      RayPointInWorld(intrinsics, poses_ + kPoseBlockSize * source.image,
                      ray_times_[source.ray_time], entry.undistorted, entry.point);
    }
  });
  have_values_ = true;
  ++value_passes_;
}

void ObservationCache::ComputeJets() {
  ParallelOverObservations(size(), num_threads_, [this](int o) {
    const Source& source = sources_[o];
    CachedObservation& entry = entries_[o];
    const double* intrinsics_values = intrinsics_ + kNumIntrinsics * source.camera;
    Jet16 intrinsics[kNumIntrinsics];
    for (int c = 0; c < kNumIntrinsics; ++c) {
      intrinsics[c] = Jet16(intrinsics_values[c], kCacheIntrinsicsOffset + c);
    }
    const Jet16 pixel[2] = {Jet16(source.pixel[0]), Jet16(source.pixel[1])};
    Jet16 undistorted[2];
    UndistortPixel(intrinsics, pixel, undistorted);
    for (int r = 0; r < 2; ++r) {
      entry.undistorted[r] = undistorted[r].a;
      for (int c = 0; c < kNumIntrinsics; ++c) {
        entry.d_undistorted[kNumIntrinsics * r + c] = undistorted[r].v[kCacheIntrinsicsOffset + c];
      }
    }
    if (source.ray_time < 0) return;
    Jet16 pose[kPoseBlockSize];
    const double* pose_values = poses_ + kPoseBlockSize * source.image;
    for (int p = 0; p < kPoseBlockSize; ++p) pose[p] = Jet16(pose_values[p], kCachePoseOffset + p);
    const Jet16 ray_time(ray_times_[source.ray_time], kCacheRayTimeOffset);
    Jet16 point[3];
    RayPointInWorld(intrinsics, pose, ray_time, undistorted, point);
    for (int r = 0; r < 3; ++r) {
      entry.point[r] = point[r].a;
      for (int c = 0; c < kCacheNumLocal; ++c)
        entry.d_point[kCacheNumLocal * r + c] = point[r].v[c];
    }
  });
  have_values_ = true;
  have_jets_ = true;
  ++jet_passes_;
}

}  // namespace raytime
