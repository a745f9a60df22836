// Issue 46: the five ways the checks failed on captures they were not built on, each reproduced
// here (every test failed before the frame verdicts; they use only what the refine stage and
// RefinePoses had then, plus the summary's JSON, so that they build against that code too):
// a part on a weak link thrown away though the phone's prior placed it, a frame with a wrong focal
// length exported, a prior in centimetres refined into something worse than itself, a prior
// without baseline refined into one point, option values that made NaN poses.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/options.h"
#include "evaluate/perturbation.h"
#include "formats/colmap_model.h"
#include "refine/refine.h"
#include "refine_stage_util.h"
#include "refine_test_util.h"
#include "temp_dir.h"
#include "testing/synthetic_scene.h"

namespace raytime {
namespace {

// A long capture with a weak link (a corridor's doorway): 14 frames on a 140° arc, each matched
// with the next three, but across frames 6 | 7 only the pair (6, 7) is left, with 40 of its
// matches, so frames 7-13 hang on the rest by one pair. The prior is a phone's: the truth off by
// 0.3° and 5 cm per frame.
SyntheticScene WeakLinkScene() {
  SyntheticSceneOptions options = ArcScene(14, 800, 0.5, 0.0, 3);
  options.arc_span_deg = 140.0;
  SyntheticScene scene = MakeSyntheticScene(options);
  std::vector<PairMatchIndices> kept;
  for (PairMatchIndices pair : scene.input.pairs) {
    const int a = std::min(pair.image1, pair.image2), b = std::max(pair.image1, pair.image2);
    const bool across = a <= 6 && b >= 7;
    if (across && !(a == 6 && b == 7)) continue;
    if (across) pair.matches.conservativeResize(std::min<Eigen::Index>(40, pair.matches.rows()), 2);
    kept.push_back(pair);
  }
  scene.input.pairs = kept;
  scene.input.prior_world_from_cam = JitterPoses(scene.ground_truth, 0.3, 0.05, 5);
  return scene;
}

const char* kAuto = "{preset: auto, num_threads: 2}";

// Eight cameras on the arc, each matched with the next three, keypoints 0.5 px noisy.
SyntheticSceneOptions EightCameras() { return ArcScene(8, 300, 0.5, 0.0, 1); }

// Preset auto's recipe for RefinePoses (configs/presets/refine/auto.yaml).
RefineOptions AutoOptions() {
  RefineOptions refine = BasinFirstConfiguration(3);
  refine.finish_noise_multiple = 2;
  refine.finish_anneal_hold_ratio = 0.01;
  return refine;
}

int ExportedFrames(const TempDir& dir) {
  return static_cast<int>(ReadColmapModelText(dir / "refined").images.size());
}

// Issue 46 item 1: a part hanging on one pair, which the phone's prior (kept by the orientation
// probe) places where the matches put it, is exported, named held_by_prior; before, loose_parts
// left the whole part out.
TEST(FrameFaultsTest, APartOnAWeakLinkThatTheTrustedPriorPlacesIsExported) {
  const SyntheticScene scene = WeakLinkScene();
  TempDir dir("frame_verdicts");
  PoseSet refined;
  const nlohmann::json summary = RunRefine(SceneInputsOf(scene), dir, &refined, kAuto);
  RunExport(dir);
  EXPECT_EQ(ExportedFrames(dir), 14) << summary["warnings"].dump();
  ASSERT_TRUE(summary["frame_verdicts"].is_object()) << summary.dump();
  for (int i = 0; i < 14; ++i) {
    EXPECT_EQ(summary["frame_verdicts"][Name(i)]["verdict"], i < 7 ? "held" : "held_by_prior")
        << Name(i) << ": " << summary["frame_verdicts"][Name(i)].dump();
  }
  EXPECT_EQ(summary["prior_trust"]["source"], "probe");
  const nlohmann::json* named = FindWarning(summary, "held_by_prior");
  ASSERT_NE(named, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*named)["images"].size(), 7u);
  // And the part is where the truth is.
  std::vector<Rigid3> solution;
  for (int i = 0; i < 14; ++i) solution.push_back(refined.world_from_cam.at(Name(i)));
  EXPECT_LT(Errors(solution, scene.ground_truth, "sim3").mean_rotation_deg, 0.1);
}

// The same part, but the prior (stated good to 0.5°) has it 4° off where the one pair holds it:
// the evidence does not agree on where it is, and it is doubted, the disagreement said.
TEST(FrameFaultsTest, APartOnAWeakLinkThatTheTrustedPriorContradictsIsDoubted) {
  SyntheticScene scene = WeakLinkScene();
  const Eigen::Vector3d hinge = scene.ground_truth[7].translation;
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(4.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  for (int i = 7; i < 14; ++i) {
    Rigid3& prior = scene.input.prior_world_from_cam[i];
    prior.rotation = (turn * prior.rotation).normalized();
    prior.translation = hinge + turn * (prior.translation - hinge);
  }
  TempDir dir("frame_verdicts");
  PoseSet refined;
  const nlohmann::json summary =
      RunRefine(SceneInputsOf(scene), dir, &refined,
                "{preset: gnc, num_threads: 2, trust_region: false, orientation_weight: 0}",
                Provenance{"test", {}, "", ""}, nullptr, {{"sigma_deg", 0.5}, {"sigma_m", 0.1}});
  RunExport(dir);
  EXPECT_EQ(ExportedFrames(dir), 7);
  EXPECT_EQ(summary["prior_trust"]["source"], "stated");
  ASSERT_TRUE(summary["frame_verdicts"].is_object()) << summary["warnings"].dump();
  for (int i = 7; i < 14; ++i) {
    const nlohmann::json& verdict = summary["frame_verdicts"][Name(i)];
    EXPECT_EQ(verdict["verdict"], "doubted") << verdict.dump();
    EXPECT_EQ(verdict["reason"], "loose_part");
    EXPECT_NE(verdict["detail"].get<std::string>().find("disagrees"), std::string::npos);
  }
}

// Issue 46 item 2: one image of eight given a focal length 1.4x its true one is placed where its
// rays fit best, far off; it is now doubted for its intrinsics (with the factor that explains its
// matches) and left out, and every frame warning lists its images.
TEST(FrameFaultsTest, AFrameWithAWrongFocalLengthIsNamedAndNotExported) {
  SyntheticSceneOptions options = ArcScene(8, 400, 0.5, 0.0, 1);
  options.focal_drift = 1e-9;  // a camera per image
  SyntheticScene scene = MakeSyntheticScene(options);
  scene.input.prior_world_from_cam = PerturbedPrior(scene, 2.0, 1);
  scene.input.cameras[3].params[kFx] *= 1.4;
  scene.input.cameras[3].params[kFy] *= 1.4;
  TempDir dir("frame_verdicts");
  PoseSet refined;
  const nlohmann::json summary = RunRefine(SceneInputsOf(scene), dir, &refined, kAuto);
  RunExport(dir);
  EXPECT_EQ(ExportedFrames(dir), 7);
  ASSERT_TRUE(summary["frame_verdicts"].is_object()) << summary["warnings"].dump();
  const nlohmann::json& verdict = summary["frame_verdicts"]["0003.jpg"];
  EXPECT_EQ(verdict["verdict"], "doubted") << summary["warnings"].dump();
  EXPECT_EQ(verdict["reason"], "intrinsics") << verdict.dump();
  for (const auto& warning : summary["warnings"]) {
    if (warning["code"] != "inconsistent_pairs") continue;
    const auto& images = warning["images"];
    EXPECT_NE(std::find(images.begin(), images.end(), "0003.jpg"), images.end()) << warning.dump();
  }
  const nlohmann::json* named = FindWarning(summary, "wrong_intrinsics");
  ASSERT_NE(named, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*named)["images"], nlohmann::json::array({"0003.jpg"}));
  for (int i = 0; i < 8; ++i) {
    if (i == 3) continue;
    EXPECT_EQ(summary["frame_verdicts"][Name(i)]["verdict"], "held") << Name(i);
  }
}

// Issue 46 item 3: the prior's unit does not change the solve. The same 4° prior in metres,
// centimetres, millimetres and kilometres gives the same poses up to scale (before, centimetres
// made it worse than the prior itself).
TEST(FrameFaultsTest, ThePriorsUnitDoesNotChangeTheSolve) {
  SyntheticScene scene = MakeSyntheticScene(EightCameras());
  const std::vector<Rigid3> prior = PerturbedPrior(scene, 4.0, 2);
  const RefineOptions refine = AutoOptions();
  std::vector<Rigid3> metres;
  for (const double unit : {1.0, 100.0, 1000.0, 0.001}) {
    SCOPED_TRACE(unit);
    scene.input.prior_world_from_cam = prior;
    for (Rigid3& pose : scene.input.prior_world_from_cam) pose.translation *= unit;
    RefineOutput output;
    RefinePoses(scene.input, refine, &output);
    EXPECT_LT(Errors(output.world_from_cam, scene.ground_truth, "sim3").mean_rotation_deg, 0.1);
    if (unit == 1.0) {
      metres = output.world_from_cam;
      continue;
    }
    for (size_t i = 0; i < metres.size(); ++i) {
      EXPECT_LT(
          RotationDistance(metres[i].rotation, output.world_from_cam[i].rotation) * 180 / M_PI,
          1e-3)
          << i;
      EXPECT_LT((output.world_from_cam[i].translation / unit - metres[i].translation).norm(),
                1e-4 * scene.ground_truth.size())
          << i;
    }
  }
}

// Issue 46 item 4: a prior with every centre at one point and the rotations right (a gyro's) was
// refined into cameras 1e-7 apart and accepted. The centres now come from the matches: spread
// out, the shape right, and the run says so.
TEST(FrameFaultsTest, APriorWithoutBaselineGetsItsCentresFromTheMatches) {
  SyntheticScene scene = MakeSyntheticScene(EightCameras());
  scene.input.prior_world_from_cam = scene.ground_truth;
  for (Rigid3& pose : scene.input.prior_world_from_cam) pose.translation.setZero();
  const RefineOptions refine = AutoOptions();
  RefineOutput output;
  const RefineSummary summary = RefinePoses(scene.input, refine, &output);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : output.world_from_cam) centroid += pose.translation / 8.0;
  double spread = 0.0;
  for (const Rigid3& pose : output.world_from_cam) {
    spread = std::max(spread, (pose.translation - centroid).norm());
  }
  EXPECT_GT(spread, 0.1);  // the median ray time is 1
  const PoseErrorSummary errors = Errors(output.world_from_cam, scene.ground_truth, "sim3");
  EXPECT_LT(errors.mean_rotation_deg, 0.1);
  EXPECT_LT(errors.mean_centre_relative, 0.01);
  bool said = false;
  const nlohmann::json json = summary.ToJson();
  for (const auto& warning : json["warnings"]) said |= warning["code"] == "prior_without_baseline";
  EXPECT_TRUE(said);
}

// Issue 46 item 5: option values that made nonsense (NaN poses, a prior 10^12 m off exported as
// refined) are refused where they are read, and a non-finite prior is refused by name.
TEST(FrameFaultsTest, OptionValuesThatMakeNonsenseAreRefused) {
  for (const char* yaml :
       {"{source: perturb, level_deg: 4, translation_per_deg: 1.0e308}",
        "{source: perturb, level_deg: 4, translation_unit: metres, translation_per_deg: 1.0e12}",
        "{source: perturb, level_deg: 4, translation_per_deg: 2}"}) {
    SCOPED_TRACE(yaml);
    std::unique_ptr<Stage> stage = CreateStage("prior");
    EXPECT_THROW(stage->Configure(YAML::Load(yaml), "test"), InputError);
  }
  PerturbationOptions perturbation;
  perturbation.translation_per_deg = 1e308;
  EXPECT_THROW(ValidateOptions(perturbation, "prior"), InputError);
  RefineOptions refine;
  refine.position_weight = 1e300;
  EXPECT_THROW(ValidateOptions(refine, "refine"), InputError);
}

// A solve started from centres kilometres off (a prior 250 scene distances off per frame) is not
// exported as refined unless its frames are right.
TEST(FrameFaultsTest, AFrameHeldIsRightOrDoubtedFromAnAbsurdPrior) {
  SyntheticScene scene = MakeSyntheticScene(EightCameras());
  scene.input.prior_world_from_cam = JitterPoses(scene.ground_truth, 4.0, 4000.0, 9);
  const RefineOptions refine = AutoOptions();
  RefineOutput output;
  const RefineSummary summary = RefinePoses(scene.input, refine, &output);
  const nlohmann::json verdicts = summary.ToJson()["frame_verdicts"];
  std::vector<Rigid3> held, truth;
  for (size_t i = 0; i < output.world_from_cam.size(); ++i) {
    if (verdicts.is_array() && verdicts[i]["verdict"] != "held") continue;
    held.push_back(output.world_from_cam[i]);
    truth.push_back(scene.ground_truth[i]);
  }
  if (held.size() >= 3) {
    const PoseErrorSummary errors = Errors(held, truth, "sim3");
    for (const auto& frame : errors.frames) EXPECT_LT(frame.rotation_deg, 1.0);
  }
}

}  // namespace
}  // namespace raytime
