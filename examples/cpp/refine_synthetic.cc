// raytime's refiner as a library: a synthetic scene (cameras on an arc 16 m from points within 4 m,
// keypoints with 0.5 px noise), its true poses perturbed by 4 degrees per frame as the prior
// (evaluate/perturbation.h, the demo's protocol), refined by RefinePoses (refine/refine.h), and
// the mean rotation error after Sim(3) alignment before and after (evaluate/pose_errors.h).
// Exit status 0 when the refiner brings the error below 0.5 degrees.
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/types.h"
#include "evaluate/perturbation.h"
#include "evaluate/pose_errors.h"
#include "refine/refine.h"

namespace {

constexpr int kCameras = 8;
constexpr int kPoints = 300;

// world_from_cam of a camera at `centre` looking at the origin (OpenCV axes: x right, y down, z
// forward).
raytime::Rigid3 LookingAtOrigin(const Eigen::Vector3d& centre) {
  const Eigen::Vector3d z = (-centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitY()).normalized();
  Eigen::Matrix3d rotation;
  rotation << x, z.cross(x), z;
  return raytime::Rigid3(Eigen::Quaterniond(rotation), centre);
}

std::string ImageName(int image) { return "image" + std::to_string(image) + ".jpg"; }

raytime::PoseSet Named(const std::vector<raytime::Rigid3>& world_from_cam) {
  raytime::PoseSet poses;
  for (int i = 0; i < static_cast<int>(world_from_cam.size()); ++i) {
    poses.world_from_cam[ImageName(i)] = world_from_cam[i];
  }
  return poses;
}

double MeanRotationErrorDeg(const raytime::PoseSet& estimate, const raytime::PoseSet& truth) {
  return raytime::ComputePoseErrors(estimate, truth, raytime::PoseErrorOptions()).mean_rotation_deg;
}

}  // namespace

int main() {
  // The refiner logs every GNC stage through spdlog's default logger (stdout); warnings only here.
  spdlog::set_level(spdlog::level::warn);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, 0.5);  // pixels

  raytime::RefineInput input;
  raytime::CameraIntrinsics camera;
  camera.width = 1536;
  camera.height = 1024;
  camera.params = {1400.0, 1400.0, 768.0, 512.0, 0.0, 0.0, 0.0, 0.0};
  input.cameras = {camera};
  input.camera_index.assign(kCameras, 0);

  std::vector<Eigen::Vector3d> points;
  while (static_cast<int>(points.size()) < kPoints) {
    const double x = 4.0 * uniform(rng);
    const double y = 4.0 * uniform(rng);
    const double z = 4.0 * uniform(rng);
    if (x * x + y * y + z * z < 16.0) points.emplace_back(x, y, z);
  }
  std::vector<raytime::Rigid3> truth;
  for (int i = 0; i < kCameras; ++i) {
    const double angle = (-35.0 + 70.0 * i / (kCameras - 1)) * M_PI / 180.0;
    truth.push_back(
        LookingAtOrigin(16.0 * Eigen::Vector3d(std::sin(angle), 0.0, -std::cos(angle))));
  }

  // Every point is seen by every camera (all are in front and inside the image); keypoint k of
  // each image is point k, so a pair's matches are the rows (k, k).
  for (int i = 0; i < kCameras; ++i) {
    raytime::Keypoints keypoints(kPoints, 2);
    for (int k = 0; k < kPoints; ++k) {
      const Eigen::Vector3d p = truth[i].Inverse() * points[k];
      keypoints(k, 0) = camera.fx() * p.x() / p.z() + camera.cx() + noise(rng);
      keypoints(k, 1) = camera.fy() * p.y() / p.z() + camera.cy() + noise(rng);
    }
    input.keypoints.push_back(keypoints);
    input.names.push_back(ImageName(i));
  }
  for (int i = 0; i < kCameras; ++i) {
    for (int j = i + 1; j < kCameras && j <= i + 3; ++j) {
      raytime::PairMatchIndices pair;
      pair.image1 = i;
      pair.image2 = j;
      pair.matches.resize(kPoints, 2);
      for (int k = 0; k < kPoints; ++k) pair.matches.row(k) << k, k;
      input.pairs.push_back(pair);
    }
  }

  raytime::PerturbationOptions perturbation;
  perturbation.level_deg = 4.0;
  const raytime::PoseSet prior = raytime::PerturbPoses(Named(truth), perturbation);
  for (int i = 0; i < kCameras; ++i) {
    input.prior_world_from_cam.push_back(prior.world_from_cam.at(ImageName(i)));
  }

  // The `auto` preset's recipe and trust region (configs/presets/refine/auto.yaml): the defaults'
  // trust region returns the prior of a solve that moved a camera more than 3.5°, and this prior
  // is 4° off.
  raytime::RefineOptions options;
  options.recipe = raytime::RefineRecipe::kBasinFirst;
  options.trust_region = false;
  raytime::RefineOutput output;
  const raytime::RefineSummary summary = raytime::RefinePoses(input, options, &output);

  const double before = MeanRotationErrorDeg(prior, Named(truth));
  const double after = MeanRotationErrorDeg(Named(output.world_from_cam), Named(truth));
  std::printf(
      "%d cameras, %d points: mean rotation error after Sim(3) %.3f deg (prior) -> %.3f deg "
      "(refined), %d iterations, prior returned by a guardrail: %s\n",
      kCameras, kPoints, before, after, summary.total_iterations,
      summary.guardrails.returned_prior ? "yes" : "no");
  return after < 0.5 ? 0 : 1;
}
