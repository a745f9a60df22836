// Per-frame doubt (refine/checks/frame_doubt.h, issue 30 item 3) on a synthetic scene with known
// poses: a frame whose solved pose moved far from its prior while its observations say it stayed
// (what wrong intrinsics do) is doubted; a frame whose prior was wrong and whose solved pose fits
// its observations (a tracking glitch the solve fixed) is not; nor a frame that only fits worse.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "refine/checks/frame_doubt.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

struct FrameDoubtScene {
  std::vector<Rigid3> truth;
  std::vector<Eigen::Vector3d> points;
  CameraIntrinsics camera;
};

// Eight cameras on an arc of radius 10 looking at 150 points near the origin.
FrameDoubtScene MakeFrameDoubtScene() {
  FrameDoubtScene scene;
  scene.camera.width = 640;
  scene.camera.height = 480;
  scene.camera.params = {500, 500, 320, 240, 0, 0, 0, 0};
  for (int i = 0; i < 8; ++i) {
    const double a = 0.1 * (i - 3.5);
    const Eigen::Vector3d centre(10 * std::sin(a), 0.2 * i, -10 * std::cos(a));
    const Eigen::Vector3d z = (-centre).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d(0, 1, 0).cross(z).normalized();
    Eigen::Matrix3d r;
    r << x, z.cross(x), z;
    scene.truth.emplace_back(Eigen::Quaterniond(r), centre);
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-2, 2);
  for (int k = 0; k < 150; ++k) scene.points.push_back(DrawVector3([&] { return u(rng); }));
  return scene;
}

struct FrameDoubtInput {
  Eigen::VectorXi image;
  Eigen::Matrix<double, Eigen::Dynamic, 2> pixel;
  Eigen::VectorXd ray_time;
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
};

// Every point observed in every image from `observed_from` (pixels with 0.3 px of noise, plus
// `extra_noise_px` in image `noisy`), its ray time the distance from `solution`'s centre; matches
// between images one and two apart.
FrameDoubtInput Observe(const FrameDoubtScene& scene, const std::vector<Rigid3>& observed_from,
                        const std::vector<Rigid3>& solution, int noisy, double extra_noise_px) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 0.3);
  const int n = static_cast<int>(observed_from.size());
  const int m = static_cast<int>(scene.points.size());
  FrameDoubtInput in;
  in.image.resize(n * m);
  in.pixel.resize(n * m, 2);
  in.ray_time.resize(n * m);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < m; ++k) {
      const Eigen::Vector3d p = observed_from[i].Inverse() * scene.points[k];
      Eigen::Vector2d u;
      ProjectPinhole(scene.camera.params.data(), p.data(), u.data());
      const double scale = 1.0 + (i == noisy ? extra_noise_px / 0.3 : 0.0);
      const double dy = noise(rng), dx = noise(rng);
      u += scale * Eigen::Vector2d(dx, dy);
      in.image(i * m + k) = i;
      in.pixel.row(i * m + k) = u.transpose();
      in.ray_time(i * m + k) = (scene.points[k] - solution[i].translation).norm();
    }
  }
  std::vector<std::pair<int, int>> rows;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j <= i + 2 && j < n; ++j) {
      for (int k = 0; k < m; ++k) rows.emplace_back(i * m + k, j * m + k);
    }
  }
  in.matches.resize(static_cast<Eigen::Index>(rows.size()), 2);
  for (size_t r = 0; r < rows.size(); ++r) in.matches.row(r) << rows[r].first, rows[r].second;
  return in;
}

// Every frame's prior a few centimetres off the truth, as a phone's.
std::vector<Rigid3> PhonePrior(const std::vector<Rigid3>& truth) {
  std::vector<Rigid3> prior = truth;
  for (size_t i = 0; i < prior.size(); ++i) {
    prior[i].translation += Eigen::Vector3d(0.03 * std::cos(i), 0.02, -0.03 * std::sin(i));
  }
  return prior;
}

FrameDoubtVerdict CheckDoubtsOf(const FrameDoubtScene& scene, const std::vector<Rigid3>& prior,
                                const std::vector<Rigid3>& solution, const FrameDoubtInput& in) {
  return CheckFrameDoubts(prior, solution,
                          std::vector<CameraIntrinsics>(prior.size(), scene.camera), in.image,
                          in.pixel, in.ray_time, in.matches);
}

TEST(FrameDoubtTest, AFrameThatMovedAwayFromWhatItSeesIsDoubted) {
  const FrameDoubtScene scene = MakeFrameDoubtScene();
  const std::vector<Rigid3> prior = PhonePrior(scene.truth);
  // A healthy solve: the truth.
  const FrameDoubtVerdict healthy =
      CheckDoubtsOf(scene, prior, scene.truth, Observe(scene, scene.truth, scene.truth, -1, 0));
  ASSERT_TRUE(healthy.checked);
  EXPECT_TRUE(healthy.images.empty());
  EXPECT_NEAR(healthy.median_pair_residual_px, 0.3, 0.2);

  // Frame 5's solved centre 2 m forward of where its images were taken (a focal length 1.5x
  // too long is absorbed so): far beyond the others' few centimetres, and its pairs fit worse.
  std::vector<Rigid3> moved = scene.truth;
  moved[5].translation += 2.0 * (moved[5].rotation * Eigen::Vector3d::UnitZ());
  const FrameDoubtVerdict doubted =
      CheckDoubtsOf(scene, prior, moved, Observe(scene, scene.truth, moved, -1, 0));
  EXPECT_EQ(doubted.images, std::vector<int>{5}) << nlohmann::json(doubted).dump();
  EXPECT_GT(doubted.centre_change[5], doubted.centre_change_threshold);
  EXPECT_GT(doubted.residual_ratio[5], 1.25);
}

TEST(FrameDoubtTest, AGlitchTheSolveFixedAndAFrameThatOnlyFitsWorseAreNotDoubted) {
  const FrameDoubtScene scene = MakeFrameDoubtScene();
  // The phone's pose of frame 5 jumped 2 m; the solve put it back where its images were taken.
  std::vector<Rigid3> prior = PhonePrior(scene.truth);
  prior[5].translation += Eigen::Vector3d(2.0, 0, 0);
  const FrameDoubtVerdict glitch =
      CheckDoubtsOf(scene, prior, scene.truth, Observe(scene, scene.truth, scene.truth, -1, 0));
  EXPECT_TRUE(glitch.images.empty()) << nlohmann::json(glitch).dump();
  EXPECT_GT(glitch.centre_change[5], glitch.centre_change_threshold);

  // Frame 2's keypoints are noisier (motion blur) but it moved like the others.
  const FrameDoubtVerdict blurred = CheckDoubtsOf(scene, PhonePrior(scene.truth), scene.truth,
                                                  Observe(scene, scene.truth, scene.truth, 2, 1.5));
  EXPECT_TRUE(blurred.images.empty()) << nlohmann::json(blurred).dump();
  EXPECT_GT(blurred.residual_ratio[2], 1.25);
}

}  // namespace
}  // namespace raytime
