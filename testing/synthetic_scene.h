// Synthetic scenes for the refiner's tests and benchmark: cameras on an arc looking at points 8–25
// m away (the depth range of the shared Strecha scenes, SPEC §8), keypoints projected with shared
// or per-image intrinsics (optionally distorted and noisy), matches between nearby cameras.
// Everything is deterministic for a seed.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "core/types.h"
#include "refine/refine.h"

namespace raytime {

struct SyntheticSceneOptions {
  int num_cameras = 8;
  int num_points = 300;
  double arc_radius_m = 16.0;   // camera distance from the scene centre
  double arc_span_deg = 70.0;   // angle the arc covers
  double point_radius_m = 7.0;  // points uniform in a ball around the centre (depths ~9–23 m)
  bool distortion = false;      // OpenCV k1, k2, p1, p2 of a mild barrel lens
  double pixel_noise = 0.0;     // standard deviation, pixels, on the distorted keypoints
  // Pairs (i, j) with 0 < j - i <= max_pair_gap are matched; 0 matches every pair.
  int max_pair_gap = 2;
  // Fraction of each pair's matches whose second keypoint is replaced by a random one.
  double outlier_fraction = 0.0;
  // Per-image intrinsics, as phone captures record them (MobileBrick's focal drifts 0.9–2.9 % per
  // scene, paper §4.6): image i's fx and fy are the shared camera's times (1 + focal_drift · u_i)
  // and its principal point moves by principal_point_drift_px · (v_i, w_i), u, v, w uniform in
  // [-1, 1] from a generator of their own (the rest of the scene is the same as without drift).
  // Both 0: one camera for all images.
  double focal_drift = 0.0;
  double principal_point_drift_px = 0.0;
  uint64_t seed = 1;
};

struct SyntheticScene {
  // prior_world_from_cam = ground truth (tests overwrite it); cameras: one, or one per image
  // (camera_index i for image i) with a drift.
  RefineInput input;
  std::vector<Rigid3> ground_truth;
  std::vector<Eigen::Vector3d> points;
  // Per camera and point: keypoint index, or -1 when the point is not visible.
  std::vector<std::vector<int>> keypoint_of_point;
};

// Shared intrinsics of the scenes: 1536 x 1024 px (the shared Strecha images), f ~ 1400 px.
CameraIntrinsics SyntheticIntrinsics(bool distortion);

// The scene most refine tests solve: `cameras` on the arc, each matched with the next three, about
// `points` points, keypoints `noise_px` noisy (standard deviation) and an `outliers` fraction of
// each pair's matches wrong, drawn from `seed`; the other options at their defaults.
SyntheticSceneOptions ArcScene(int cameras, int points, double noise_px, double outliers,
                               uint64_t seed);

SyntheticScene MakeSyntheticScene(const SyntheticSceneOptions& options);

// A pair's matches from (keypoint in image1, keypoint in image2) rows.
PairMatchIndices MakePairMatches(int image1, int image2,
                                 const std::vector<std::pair<uint32_t, uint32_t>>& rows);

// Regenerates camera `camera`'s keypoints as if it stood at `world_from_cam` (the matches keep
// their indices): matches that pull the solve to a wrong pose, for the guardrail tests.
void ReprojectCamera(SyntheticScene* scene, int camera, const Rigid3& world_from_cam);

// Image names "0000.jpg", ... and pose sets for evaluate/ (pose errors, perturbation).
PoseSet ToPoseSet(const std::vector<Rigid3>& world_from_cam);
std::vector<Rigid3> FromPoseSet(const PoseSet& poses, int num_cameras);

}  // namespace raytime
