// The refine stage's honesty on constructed inputs (issue 13): a camera no verified pair touches
// is not exported as refined (unmatched_cameras), a match graph in pieces is refined piece by
// piece and said so (disconnected_graph), and no match at all is an error, never a copy of the
// prior. Inputs are synthetic scenes with known poses written in raytime's HDF5 schema.
#include <gtest/gtest.h>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "evaluate/pose_errors.h"
#include "pipelines/stage.h"
#include "temp_dir.h"
#include "tests/refine_synthetic.h"

namespace raytime {
namespace {

// Two synthetic scenes side by side in one image list (A: images 0-4, B: images 5-7) and, when
// asked, a ninth image with keypoints but no verified pair.
struct TwoScenes {
  ImageSet images;
  std::vector<ImageFeatures> features;
  std::vector<PairMatches> matches;
  PoseSet ground_truth;
  PoseSet prior;
};

std::string Name(int i) {
  char name[16];
  std::snprintf(name, sizeof(name), "%04d.jpg", i);
  return name;
}

TwoScenes MakeTwoScenes(bool with_lonely_image) {
  SyntheticSceneOptions a_options;
  a_options.num_cameras = 5;
  SyntheticSceneOptions b_options;
  b_options.num_cameras = 3;
  b_options.seed = 7;
  const SyntheticScene a = MakeSyntheticScene(a_options);
  const SyntheticScene b = MakeSyntheticScene(b_options);
  TwoScenes out;
  const CameraIntrinsics camera = a.input.intrinsics;
  out.images.cameras = {camera};
  const auto add = [&](const SyntheticScene& scene, int k) {
    const int index = static_cast<int>(out.images.images.size());
    out.images.images.push_back({Name(index), camera.width, camera.height, 0});
    ImageFeatures features;
    features.keypoints.resize(scene.input.keypoints[k].rows(), 4);
    features.keypoints.setZero();
    features.keypoints.leftCols<2>() = scene.input.keypoints[k].cast<float>();
    out.features.push_back(features);
    // The second scene is 100 m away, so one frame holds both; the prior is 1° off.
    Rigid3 pose = scene.ground_truth[k];
    if (&scene == &b) pose.translation += Eigen::Vector3d(100, 0, 0);
    out.ground_truth.world_from_cam[Name(index)] = pose;
    Rigid3 prior = pose;
    prior.rotation =
        (Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d::UnitY()) * prior.rotation).normalized();
    out.prior.world_from_cam[Name(index)] = prior;
  };
  for (int k = 0; k < 5; ++k) add(a, k);
  for (int k = 0; k < 3; ++k) add(b, k);
  if (with_lonely_image) add(b, 0);
  const auto pairs = [&](const SyntheticScene& scene, int offset) {
    for (const PairMatchIndices& p : scene.input.pairs) {
      PairMatches pair;
      pair.image1 = p.image1 + offset;
      pair.image2 = p.image2 + offset;
      pair.matches = p.matches;
      pair.geometry.inlier_matches = p.matches;
      out.matches.push_back(pair);
    }
  };
  pairs(a, 0);
  pairs(b, 5);
  return out;
}

// Writes the scene's HDF5 inputs and runs the refine stage (preset plain, one thread; no trust
// region: its thresholds are object-scale, these scenes are 16 m deep).
nlohmann::json RunRefine(const TwoScenes& scene, const TempDir& dir, PoseSet* refined) {
  {
    Hdf5Writer writer(dir / "inputs.h5");
    writer.WriteImages(scene.images);
    writer.WritePoseSet("prior", scene.prior, PoseRole::kPrior, Provenance{"test", {}, "", ""});
    writer.WriteFeatures(scene.features, Provenance{"test", {}, "", ""});
    writer.WriteMatches(scene.matches, Provenance{"test", {}, "", ""});
    writer.Commit();
  }
  std::unique_ptr<Stage> stage = CreateStage("refine");
  stage->Configure(YAML::Load("{preset: plain, num_threads: 1, trust_region: false}"), "test");
  StageContext context;
  context.stage_id = "refine";
  context.workdir = dir.path().string();
  context.output_path = dir / "refine.h5";
  for (const char* artifact : {"images", "features", "matches", "poses/prior"}) {
    context.artifacts[artifact] = dir / "inputs.h5";
  }
  const nlohmann::json summary = stage->Run(context);
  *refined = Hdf5Reader(context.output_path).ReadPoseSet("refined");
  return summary;
}

const nlohmann::json* FindWarning(const nlohmann::json& summary, const std::string& code) {
  for (const auto& warning : summary["warnings"]) {
    if (warning["code"] == code) return &warning;
  }
  return nullptr;
}

TEST(RefineStageTest, UnmatchedCameraIsReportedAndNotExported) {
  TempDir dir("refine_stage");
  const TwoScenes scene = MakeTwoScenes(/*with_lonely_image=*/true);
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  const nlohmann::json* warning = FindWarning(summary, "unmatched_cameras");
  ASSERT_NE(warning, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*warning)["images"], nlohmann::json::array({"0008.jpg"}));
  EXPECT_FALSE(refined.Has("0008.jpg"));
  EXPECT_EQ(refined.size(), 8u);
}

TEST(RefineStageTest, DisconnectedGraphIsRefinedPerComponentAndSaidSo) {
  TempDir dir("refine_stage");
  const TwoScenes scene = MakeTwoScenes(/*with_lonely_image=*/false);
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  const nlohmann::json* warning = FindWarning(summary, "disconnected_graph");
  ASSERT_NE(warning, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*warning)["details"]["component_sizes"], nlohmann::json::array({5, 3}));
  EXPECT_EQ((*warning)["images"], nlohmann::json::array({"0005.jpg", "0006.jpg", "0007.jpg"}));
  ASSERT_EQ(summary["components"].size(), 2u);
  // Each piece, in its own gauge, recovers its poses from the 1° prior.
  for (const auto& [begin, end] : {std::pair<int, int>{0, 5}, std::pair<int, int>{5, 8}}) {
    PoseSet estimate, truth;
    for (int i = begin; i < end; ++i) {
      estimate.world_from_cam[Name(i)] = refined.world_from_cam.at(Name(i));
      truth.world_from_cam[Name(i)] = scene.ground_truth.world_from_cam.at(Name(i));
    }
    EXPECT_LT(ComputePoseErrors(estimate, truth, PoseErrorOptions()).mean_rotation_deg, 0.05)
        << "component starting at " << begin;
  }
}

TEST(RefineStageTest, NoVerifiedPairIsAnErrorNotACopyOfThePrior) {
  TempDir dir("refine_stage");
  TwoScenes scene = MakeTwoScenes(false);
  for (PairMatches& pair : scene.matches) pair.geometry.inlier_matches.resize(0, 2);
  PoseSet refined;
  try {
    RunRefine(scene, dir, &refined);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("nothing to refine"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "refine.h5"));
}

}  // namespace
}  // namespace raytime
