// Per-image intrinsics in the refiner (refine/solve/camera_blocks.h; issue 10 "Per-frame
// intrinsics"): synthetic scenes whose images each have their own camera, as phone captures record
// them (focal lengths a few % apart, MobileBrick's 0.9–2.9 % per scene, paper §4.6; principal
// points some pixels apart). The true per-image intrinsics, fixed, give the poses to the synthetic
// precision while one camera forced on every image does measurably worse; per-camera
// self-calibration recovers each image's focal length where a shared set cannot; on a single
// camera nothing changes; and nonsense option combinations are refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/error.h"
#include "refine/refine.h"
#include "refine/solve/camera_blocks.h"
#include "testing/synthetic_scene.h"
#include "tests/expect_pose.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

// Keypoint noise and a few wrong matches, as from a front end; with `drift`, per-image cameras
// 3 % apart in focal length and 8 px in principal point.
SyntheticSceneOptions Scene(bool drift) {
  SyntheticSceneOptions options = ArcScene(8, 300, 0.5, 0.05, 17);
  if (drift) {
    options.focal_drift = 0.03;
    options.principal_point_drift_px = 8.0;
  }
  return options;
}

// GNC without the object-scale trust region (these scenes are 16 m deep) and, as the basin
// configuration of §4.8, without the orientation prior (λR = 0), which would hold the solve
// towards the perturbed prior's rotations.
RefineOptions Options() { return BasinConfiguration(0); }

// The input with every image on one camera: the per-image cameras' median (what a refiner with
// one shared set of intrinsics would be given).
RefineInput ForcedShared(const RefineInput& input) {
  RefineInput shared = input;
  double disagreement = 0.0;
  const CameraBlocks block = SharedBlock(input, &disagreement);
  shared.cameras = block.cameras;
  shared.camera_index = block.camera_of_image;
  return shared;
}

TEST(RefineIntrinsicsTest, FixedPerImageIntrinsicsGiveThePosesForcedSharedDoesWorse) {
  // The synthetic precision: the same scene, noise and outliers with one camera.
  SyntheticScene reference = MakeSyntheticScene(Scene(false));
  reference.input.prior_world_from_cam = PerturbedPrior(reference, 4.0, 1);
  RefineOutput reference_output;
  RefinePoses(reference.input, Options(), &reference_output);
  const PoseErrorSummary precision =
      Errors(reference_output.world_from_cam, reference.ground_truth, "sim3");

  SyntheticScene scene = MakeSyntheticScene(Scene(true));
  ASSERT_EQ(scene.input.cameras.size(), 8u);
  scene.input.prior_world_from_cam = PerturbedPrior(scene, 4.0, 1);
  RefineOutput per_image, shared;
  const RefineSummary summary = RefinePoses(scene.input, Options(), &per_image);
  const RefineSummary shared_summary = RefinePoses(ForcedShared(scene.input), Options(), &shared);
  const PoseErrorSummary per_image_errors =
      Errors(per_image.world_from_cam, scene.ground_truth, "sim3");
  const PoseErrorSummary shared_errors = Errors(shared.world_from_cam, scene.ground_truth, "sim3");
  std::printf(
      "from a 4 deg prior, Sim(3) errors: one camera (no drift) %.4f deg / %.4f m; per-image "
      "intrinsics fixed %.4f deg / %.4f m; one median camera forced on them %.4f deg / %.4f m\n",
      precision.mean_rotation_deg, precision.mean_centre_m, per_image_errors.mean_rotation_deg,
      per_image_errors.mean_centre_m, shared_errors.mean_rotation_deg, shared_errors.mean_centre_m);
  EXPECT_EQ(summary.cameras.num_cameras, 8);
  EXPECT_EQ(summary.cameras.num_blocks, 8);
  EXPECT_EQ(summary.cameras.sharing, "per_camera");
  EXPECT_FALSE(summary.passes[0].self_calibration);
  EXPECT_EQ(shared_summary.cameras.num_blocks, 1);
  // The given intrinsics are returned as given.
  EXPECT_EQ(per_image.cameras, scene.input.cameras);
  // Per-image intrinsics: the synthetic precision (the noise floor of the single-camera scene,
  // within the variation between two draws of keypoint noise and outliers).
  EXPECT_LT(per_image_errors.mean_rotation_deg, 0.05);
  EXPECT_LT(per_image_errors.mean_rotation_deg, 3.0 * precision.mean_rotation_deg);
  EXPECT_LT(per_image_errors.mean_centre_m, 3.0 * precision.mean_centre_m);
  // One camera forced on them: measurably worse (by more than an order of magnitude).
  EXPECT_GT(shared_errors.mean_rotation_deg, 10.0 * per_image_errors.mean_rotation_deg);
  EXPECT_GT(shared_errors.mean_rotation_deg, 0.5);
  EXPECT_GT(shared_errors.mean_centre_m, 10.0 * per_image_errors.mean_centre_m);
}

// Every camera's focal length 1.5 % off its true value, alternately up and down, the prior exact
// (as the shared self-calibration test of refine_solve_test): per_camera self-calibration (one
// focal pair per image) finds each image's focal length where every image sees enough of the
// scene (all pairs matched, ~450 observations per camera; with ~270, in pairs up to 3 apart, the
// focal lengths of this noisy scene come out ~0.2 % off and the poses 0.1° off, the focal-depth
// trade of a single view being only weakly constrained); a shared set can only find their middle.
TEST(RefineIntrinsicsTest, PerCameraSelfCalibrationRecoversEachImagesFocal) {
  SyntheticSceneOptions scene_options = Scene(true);
  scene_options.num_points = 500;
  scene_options.max_pair_gap = 0;
  SyntheticScene scene = MakeSyntheticScene(scene_options);
  const std::vector<CameraIntrinsics> truth = scene.input.cameras;
  for (size_t c = 0; c < scene.input.cameras.size(); ++c) {
    const double scale = c % 2 == 0 ? 1.015 : 0.985;
    scene.input.cameras[c].params[kFx] *= scale;
    scene.input.cameras[c].params[kFy] *= scale;
  }
  scene.input.prior_world_from_cam = scene.ground_truth;
  RefineOptions options = Options();
  options.orientation_weight = RefineOptions().orientation_weight;
  options.refine_focal = true;
  options.intrinsics_sharing = IntrinsicsSharing::kPerCamera;
  RefineOutput per_camera;
  const RefineSummary summary = RefinePoses(scene.input, options, &per_camera);
  options.intrinsics_sharing = IntrinsicsSharing::kShared;
  RefineOutput shared;
  const RefineSummary shared_summary = RefinePoses(scene.input, options, &shared);

  const auto worst_focal_error = [&](const std::vector<CameraIntrinsics>& cameras) {
    double worst = 0.0;
    for (size_t c = 0; c < truth.size(); ++c) {
      for (const int k : {kFx, kFy}) {
        worst = std::max(worst, std::abs(cameras[c].params[k] / truth[c].params[k] - 1.0));
      }
    }
    return worst;
  };
  const double start_error = worst_focal_error(scene.input.cameras);
  const double per_camera_error = worst_focal_error(per_camera.cameras);
  const double shared_error = worst_focal_error(shared.cameras);
  const double per_camera_deg =
      Errors(per_camera.world_from_cam, scene.ground_truth, "sim3").mean_rotation_deg;
  const double shared_deg =
      Errors(shared.world_from_cam, scene.ground_truth, "sim3").mean_rotation_deg;
  std::printf(
      "focal self-calibration from %.2f %% off: per_camera worst focal error %.3f %% (%.4f deg "
      "Sim(3)), shared %.3f %% (%.4f deg), fewest observations on a camera %d\n",
      100 * start_error, 100 * per_camera_error, per_camera_deg, 100 * shared_error, shared_deg,
      summary.cameras.min_block_observations);
  EXPECT_TRUE(summary.passes[0].self_calibration);
  EXPECT_EQ(summary.cameras.num_blocks, 8);
  EXPECT_GT(summary.cameras.min_block_observations, 400);
  EXPECT_LT(per_camera_error, 0.005);  // from 1.5 %, cameras up to 6 % apart
  EXPECT_LT(per_camera_deg, 0.05);
  // The shared set started at the median of cameras up to ~4 % apart: reported, and it cannot
  // follow them.
  EXPECT_EQ(shared_summary.cameras.num_blocks, 1);
  EXPECT_TRUE(shared_summary.cameras.cameras_differ);
  EXPECT_GT(shared_summary.cameras.max_start_disagreement_px, kSharedCameraTolerancePx);
  EXPECT_GT(shared_error, 0.01);
  EXPECT_GT(shared_deg, per_camera_deg);
  // Every camera holds the one shared set.
  for (const CameraIntrinsics& camera : shared.cameras) EXPECT_EQ(camera, shared.cameras[0]);
}

// With one camera the blocks are the paper's one shared set whichever sharing is asked for: the
// solve is the same bit for bit, the start is the camera itself (no disagreement, no warning).
// The same camera given twice, the images split between the two copies, refines to the same
// poses bit for bit with fixed intrinsics (two constant blocks, the two-block cost variant).
TEST(RefineIntrinsicsTest, OneCameraIsUnchangedWhateverTheSharing) {
  SyntheticSceneOptions scene_options = Scene(false);
  scene_options.distortion = true;
  SyntheticScene scene = MakeSyntheticScene(scene_options);
  scene.input.cameras[0].params = {1421.0, 1417.0, 762.0, 515.0, 0.0, 0.0, 0.0, 0.0};
  scene.input.prior_world_from_cam = scene.ground_truth;
  RefineOptions options = Options();
  // The orientation prior separates a principal-point shift from a common rotation.
  options.orientation_weight = RefineOptions().orientation_weight;
  options.refine_focal = options.refine_principal_point = options.refine_distortion = true;
  options.intrinsics_sharing = IntrinsicsSharing::kShared;
  RefineOutput shared, per_camera;
  const RefineSummary shared_summary = RefinePoses(scene.input, options, &shared);
  options.intrinsics_sharing = IntrinsicsSharing::kPerCamera;
  RefinePoses(scene.input, options, &per_camera);
  EXPECT_EQ(shared_summary.cameras.num_blocks, 1);
  EXPECT_EQ(shared_summary.cameras.max_start_disagreement_px, 0.0);
  EXPECT_FALSE(shared_summary.cameras.cameras_differ);
  ASSERT_EQ(shared.cameras.size(), 1u);
  EXPECT_EQ(shared.cameras, per_camera.cameras);
  ExpectSamePoses(shared.world_from_cam, per_camera.world_from_cam, "shared vs per camera");
  EXPECT_NEAR(shared.cameras[0].params[kFx] / 1400.0, 1.0, 0.005);

  scene.input.prior_world_from_cam = PerturbedPrior(scene, 2.0, 3);
  RefineOutput one, two;
  RefinePoses(scene.input, Options(), &one);
  RefineInput split = scene.input;
  split.cameras.push_back(split.cameras[0]);
  for (size_t i = 1; i < split.camera_index.size(); i += 2) split.camera_index[i] = 1;
  const RefineSummary split_summary = RefinePoses(split, Options(), &two);
  EXPECT_EQ(split_summary.cameras.num_blocks, 2);
  ExpectSamePoses(two.world_from_cam, one.world_from_cam, "one block vs two");
}

// A shared set exists only to be refined; one set cannot describe images of different sizes.
TEST(RefineIntrinsicsTest, NonsenseCombinationsAreRefused) {
  SyntheticSceneOptions scene_options = Scene(true);
  scene_options.num_cameras = 3;
  scene_options.num_points = 60;
  SyntheticScene scene = MakeSyntheticScene(scene_options);
  RefineOptions options = Options();
  options.intrinsics_sharing = IntrinsicsSharing::kShared;
  RefineOutput output;
  try {
    RefinePoses(scene.input, options, &output);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("intrinsics_sharing 'shared'"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("refine_focal"), std::string::npos) << e.what();
  }
  options.refine_focal = true;
  scene.input.cameras[1].width = 1024;
  scene.input.cameras[1].height = 1536;
  try {
    RefinePoses(scene.input, options, &output);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("one image size"), std::string::npos) << e.what();
  }
  options.intrinsics_sharing = IntrinsicsSharing::kPerCamera;
  scene.input.camera_index[2] = 5;
  try {
    RefinePoses(scene.input, options, &output);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("camera index 5"), std::string::npos) << e.what();
  }
}

// The disagreement of two cameras is where they put the same ray apart on the image: zero for
// equal cameras, a principal-point shift exactly, a focal change at the image corners.
TEST(RefineIntrinsicsTest, CameraDisagreementMeasuresPixelsOnTheImage) {
  const CameraIntrinsics a = SyntheticIntrinsics(true);
  EXPECT_EQ(CameraDisagreementPx(a, a), 0.0);
  CameraIntrinsics b = SyntheticIntrinsics(false);
  b.params[kCx] += 3.0;
  CameraIntrinsics c = SyntheticIntrinsics(false);
  EXPECT_NEAR(CameraDisagreementPx(b, c), 3.0, 1e-9);
  c.params[kFx] *= 1.01;
  c.params[kFy] *= 1.01;
  // 1 % of the distance from the principal point (770.5, 509) to the farthest sample, the
  // corner (0, 1023), in the direction from the smaller focal to the larger.
  const double corner = std::hypot(770.5, 1023.0 - 509.0);
  EXPECT_NEAR(CameraDisagreementPx(SyntheticIntrinsics(false), c), 0.01 * corner, 1e-9);
}

}  // namespace
}  // namespace raytime
