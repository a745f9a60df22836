// The reference an estimator's efficiency is measured against (issue 50): on a synthetic scene
// with known keypoint noise, a bundle adjustment with one 3D point per track (the maximum-
// likelihood estimator under Gaussian pixel noise, the classical pipeline's model) started at the
// truth, and the Cramér–Rao bound of its pose errors. Errors are those of the standard protocol,
// after the Sim(3) alignment on camera centres (evaluate/pose_errors.h, SPEC §6), so the bound
// removes the 7-dof similarity gauge the way the measured errors do. bench/efficiency_bench.cc
// reads these, docs/efficiency.md has its table.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "core/types.h"
#include "testing/synthetic_scene.h"

namespace raytime {

// One point per track: the observations (image, keypoint) the scene's matches join (union-find
// over the pairs, as a classical pipeline builds its tracks), and the true point.
struct SceneTrack {
  std::vector<std::pair<int, int>> observations;
  Eigen::Vector3d point;
};
std::vector<SceneTrack> MatchedTracks(const SyntheticScene& scene);

// Root mean square over cameras (and draws) of the rotation error, degrees, and of the centre
// error, scene units.
struct RmsPoseError {
  double rotation_deg = 0.0;
  double centre = 0.0;
};

// The bound on the Sim(3)-aligned pose errors: σ² L S⁺ Lᵀ, S the poses' Schur complement of the
// bundle adjustment's JᵀJ at the truth (points eliminated), S⁺ its inverse on all but the 7 gauge
// directions, L the linearized alignment.
RmsPoseError CramerRaoBound(const SyntheticScene& scene, const std::vector<SceneTrack>& tracks,
                            double sigma_px);

// The bundle adjustment (plain least squares: the scenes have no outliers) on `keypoints` (the
// scene's, with noise), started at the truth.
std::vector<Rigid3> BundleAdjustFromTruth(const SyntheticScene& scene,
                                          const std::vector<SceneTrack>& tracks,
                                          const std::vector<Keypoints>& keypoints);

// The keypoints with N(0, σ²) noise on each coordinate, drawn from `seed` the same way by every
// compiler and standard library.
std::vector<Keypoints> NoisyKeypoints(const std::vector<Keypoints>& keypoints, double sigma_px,
                                      uint64_t seed);

// Sums squared Sim(3)-aligned errors (evaluate/pose_errors.h) of solutions against the truth.
class RmsPoseErrorSum {
 public:
  void Add(const std::vector<Rigid3>& estimate, const std::vector<Rigid3>& truth);
  RmsPoseError Rms() const;

 private:
  double rotation_sq_ = 0.0, centre_sq_ = 0.0;
  int count_ = 0;
};

}  // namespace raytime
