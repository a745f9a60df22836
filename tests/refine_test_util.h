// Helpers shared by the refiner's tests: true ray times of a synthetic scene and perturbed
// problem states, so residuals and Jacobians are checked away from the optimum; errors against
// the ground truth and ladder-perturbed priors for the solve tests; wrong matches to a copy of
// the scene (repeated structure).
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "core/camera.h"
#include "evaluate/perturbation.h"
#include "evaluate/pose_errors.h"
#include "refine/refine_options.h"
#include "refine/solve/problem_layout.h"
#include "testing/random_draws.h"
#include "testing/synthetic_scene.h"

namespace raytime {

// Depth along the observation's unit ray of the scene point it sees: the ray time at which the
// ray point is the point.
inline std::vector<double> TrueRayTimes(const SyntheticScene& scene, const ProblemLayout& layout) {
  std::vector<double> ray_times;
  for (int o : layout.ray_time_observation) {
    const LayoutObservation& obs = layout.observations[o];
    const std::vector<int>& map = scene.keypoint_of_point[obs.image];
    const auto it = std::find(map.begin(), map.end(), obs.keypoint);
    const Eigen::Vector3d& point = scene.points[it - map.begin()];
    ray_times.push_back((point - scene.ground_truth[obs.image].translation).norm());
  }
  return ray_times;
}

// Every pose moved by `degrees` about a random axis and `metres` in a random direction.
inline std::vector<Rigid3> JitterPoses(const std::vector<Rigid3>& poses, double degrees,
                                       double metres, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Rigid3> out = poses;
  for (Rigid3& pose : out) {
    const Eigen::Vector3d axis = DrawVector3([&] { return u(rng); }).normalized();
    const Eigen::Vector3d direction = DrawVector3([&] { return u(rng); }).normalized();
    pose.rotation =
        Eigen::Quaterniond(Eigen::AngleAxisd(degrees * M_PI / 180.0, axis)) * pose.rotation;
    pose.translation += metres * direction;
  }
  return out;
}

inline std::vector<double> JitterValues(const std::vector<double>& values, double relative,
                                        uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> out = values;
  for (double& v : out) v *= 1.0 + relative * u(rng);
  return out;
}

// Errors of `estimate` against `truth` after the named alignment (sim3, se3, none).
inline PoseErrorSummary Errors(const std::vector<Rigid3>& estimate,
                               const std::vector<Rigid3>& truth, const std::string& alignment) {
  PoseErrorOptions options;
  options.alignment = alignment;
  return ComputePoseErrors(ToPoseSet(estimate), ToPoseSet(truth), options);
}

// The scene's ground truth perturbed by the ladder protocol (§4.8) at `level_deg`.
inline std::vector<Rigid3> PerturbedPrior(const SyntheticScene& scene, double level_deg, int seed) {
  PerturbationOptions perturbation;
  perturbation.level_deg = level_deg;
  perturbation.seed = seed;
  return FromPoseSet(PerturbPoses(ToPoseSet(scene.ground_truth), perturbation),
                     static_cast<int>(scene.ground_truth.size()));
}

// Repeated structure (§4.11; castle-P19's walls): in pair `p` (i, j), image j's side of every
// `every`-th match (all by default) is replaced by a new keypoint of j, the projection of the point
// moved by `shift` (e.g. 1.5 m along the vertical axis: the same window one storey over); a match
// whose copy j does not see is dropped. With every match moved the pair agrees with itself and with
// a wrong relative pose (camera j moved by -shift), not with the scene.
inline void MatchToACopy(SyntheticScene* scene, size_t p, const Eigen::Vector3d& shift,
                         int every = 1) {
  const CameraIntrinsics& intrinsics = scene->input.cameras.at(0);  // one shared camera
  PairMatchIndices& pair = scene->input.pairs[p];
  const std::vector<int>& map = scene->keypoint_of_point[pair.image1];
  Keypoints& keypoints = scene->input.keypoints[pair.image2];
  std::vector<std::pair<uint32_t, uint32_t>> rows;
  for (Eigen::Index m = 0; m < pair.matches.rows(); ++m) {
    if (m % every != 0) {
      rows.emplace_back(pair.matches(m, 0), pair.matches(m, 1));
      continue;
    }
    const auto point = std::find(map.begin(), map.end(), pair.matches(m, 0)) - map.begin();
    const Eigen::Vector3d c =
        scene->ground_truth[pair.image2].Inverse() * (scene->points[point] + shift);
    if (c.z() < 1.0) continue;
    double undistorted[2], distorted[2];
    ProjectPinhole(intrinsics.params.data(), c.data(), undistorted);
    DistortPixel(intrinsics.params.data(), undistorted, distorted);
    if (distorted[0] < 0 || distorted[1] < 0 || distorted[0] > intrinsics.width ||
        distorted[1] > intrinsics.height) {
      continue;
    }
    const Eigen::Index row = keypoints.rows();
    keypoints.conservativeResize(row + 1, 2);
    keypoints.row(row) << distorted[0], distorted[1];
    rows.emplace_back(pair.matches(m, 0), static_cast<uint32_t>(row));
  }
  pair.matches.resize(static_cast<Eigen::Index>(rows.size()), 2);
  for (size_t m = 0; m < rows.size(); ++m) {
    pair.matches(static_cast<Eigen::Index>(m), 0) = rows[m].first;
    pair.matches(static_cast<Eigen::Index>(m), 1) = rows[m].second;
  }
}

// The basin configuration of the paper's ladders (§4.8) on two threads: no trust region (a
// perturbation exceeds its envelope by construction), no orientation prior (λR = 0, which would
// hold the solve towards the perturbed prior's rotations), at most `cap` matches per pair (0: all).
inline RefineOptions BasinConfiguration(int cap) {
  RefineOptions options;
  options.trust_region = false;
  options.orientation_weight = 0.0;
  options.max_matches_per_pair = cap;
  options.num_threads = 2;
  return options;
}

// The basin-first recipe (the `auto` preset's) without a trust region on two threads, with up to
// `removal_rounds` rounds of wrong-pair removal.
inline RefineOptions BasinFirstConfiguration(int removal_rounds) {
  RefineOptions options;
  options.recipe = RefineRecipe::kBasinFirst;
  options.trust_region = false;
  options.max_pair_removal_rounds = removal_rounds;
  options.num_threads = 2;
  return options;
}

}  // namespace raytime
