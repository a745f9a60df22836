// The refine stage's honesty on constructed inputs (issue 13): a camera no verified pair touches
// is not exported as refined (unmatched_cameras), a match graph in pieces is refined piece by
// piece and said so (disconnected_graph), and no match at all is an error, never a copy of the
// prior. Images with their own cameras (issue 10, per-frame intrinsics) are refined with them, and
// self-calibrated cameras are written and exported per camera (one when shared, cameras_shared).
// Inputs are synthetic scenes with known poses written in raytime's HDF5 schema.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "evaluate/pose_errors.h"
#include "formats/colmap_model.h"
#include "pipelines/stage.h"
#include "refine_stage_util.h"
#include "refine_test_util.h"
#include "temp_dir.h"
#include "testing/synthetic_scene.h"
#include "tests/run_stage.h"

namespace raytime {
namespace {

// Two synthetic scenes side by side in one image list (A: images 0-4, B: images 5-7) and, when
// asked, a ninth image with keypoints but no verified pair.
SceneInputs MakeTwoScenes(bool with_lonely_image, bool exact_prior_for_b = false) {
  SyntheticSceneOptions a_options;
  a_options.num_cameras = 5;
  SyntheticSceneOptions b_options;
  b_options.num_cameras = 3;
  b_options.seed = 7;
  const SyntheticScene a = MakeSyntheticScene(a_options);
  const SyntheticScene b = MakeSyntheticScene(b_options);
  SceneInputs out;
  const CameraIntrinsics camera = a.input.cameras.at(0);
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
    if (exact_prior_for_b && &scene == &b) {
      out.prior.world_from_cam[Name(index)] = prior;
      return;
    }
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

// One synthetic scene whose 6 images each have their own camera (focal 3 %, principal point 8 px
// apart), the prior 1° off; `cameras` receives the true cameras (the inputs' may be changed).
SceneInputs MakePerImageScene(std::vector<CameraIntrinsics>* cameras) {
  SyntheticSceneOptions options = ArcScene(6, 300, 0.0, 0.0, 1);
  options.focal_drift = 0.03;
  options.principal_point_drift_px = 8.0;
  SyntheticScene scene = MakeSyntheticScene(options);
  *cameras = scene.input.cameras;
  for (Rigid3& prior : scene.input.prior_world_from_cam) {
    prior.rotation =
        (Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d::UnitY()) * prior.rotation).normalized();
  }
  return SceneInputsOf(scene);
}

// A trust region far below the correction of a 1°-off prior: the solve keeps the orientations
// (the orientation prior holds this common 1° rotation, a gauge) but moves the centres ~0.16 m.
const char* kTinyTrustRegion =
    "{preset: plain, num_threads: 1, trust_region: true, trust_region_rotation_deg: 10, "
    "trust_region_translation_m: 0.05}";

// A prior the bootstrap made, or one the prior stage's repair replaced from it, has rotations
// estimated from the same matches: preset auto finishes without an orientation prior towards them
// and does not probe it; any other prior (a repair that kept it included) is probed.
TEST(RefineStageTest, AutoUsesNoOrientationPriorFromTheBootstrap) {
  std::vector<CameraIntrinsics> cameras;
  const SceneInputs scene = MakePerImageScene(&cameras);
  const std::string options = "{preset: auto, num_threads: 1}";
  struct Case {
    Provenance provenance;
    nlohmann::json repair;
    bool from_bootstrap;
  };
  const nlohmann::json repaired_source = {{"source", "pose_set"}, {"repair", "auto"}};
  const std::vector<Case> cases = {
      {Provenance{"prior", {{"source", "capture"}}, "", ""}, nullptr, false},
      {Provenance{"prior", {{"source", "bootstrap"}}, "", ""}, nullptr, true},
      {Provenance{"prior", repaired_source, "", ""},
       {{"mode", "replace"}, {"pose_set", "prior"}},
       true},
      {Provenance{"prior", repaired_source, "", ""},
       {{"mode", "none"}, {"pose_set", "prior"}},
       false},
      // The repair record of another pose set says nothing about this one.
      {Provenance{"prior", repaired_source, "", ""},
       {{"mode", "rotations"}, {"pose_set", "prior@other"}},
       false}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.provenance.options.dump() + " " + c.repair.dump());
    const bool from_bootstrap = c.from_bootstrap;
    TempDir dir("refine_stage");
    PoseSet refined;
    const nlohmann::json summary = RunRefine(scene, dir, &refined, options, c.provenance, c.repair);
    const nlohmann::json& probe = summary["orientation_prior"];
    EXPECT_EQ(probe["prior_from_matches"], from_bootstrap) << probe;
    std::vector<std::string> passes;
    for (const auto& pass : summary["passes"]) passes.push_back(pass["name"]);
    if (from_bootstrap) {
      EXPECT_FALSE(probe["kept"]);
      EXPECT_EQ(passes, std::vector<std::string>({"basin", "finish", "finish_anneal"}));
      EXPECT_EQ(summary["passes"][1]["orientation_weight"], 0.0);
    } else {
      EXPECT_EQ(passes, std::vector<std::string>(
                            {"basin", "orientation_probe", "finish", "finish_anneal"}));
    }
    // The anneal holds the rotations at the finish's own with 0.01 x the finish's λR (auto's
    // finish_anneal_hold_ratio): none after a λR = 0 finish.
    EXPECT_DOUBLE_EQ(
        summary["passes"].back()["orientation_weight"].get<double>(),
        0.01 * summary["passes"][passes.size() - 2]["orientation_weight"].get<double>());
    EXPECT_LT(ComputePoseErrors(refined, scene.ground_truth, PoseErrorOptions()).mean_rotation_deg,
              0.05);
  }
  // A damaged repair record is an input error naming the file, not a guess either way.
  TempDir dir("refine_stage");
  PoseSet refined;
  try {
    RunRefine(scene, dir, &refined, options, Provenance{"prior", repaired_source, "", ""},
              nlohmann::json::array({"replace"}));
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("inputs.h5: /json/prior_repair"), std::string::npos)
        << e.what();
  }
}

TEST(RefineStageTest, UnmatchedCameraIsReportedAndNotExported) {
  TempDir dir("refine_stage");
  const SceneInputs scene = MakeTwoScenes(/*with_lonely_image=*/true);
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
  const SceneInputs scene = MakeTwoScenes(/*with_lonely_image=*/false);
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  const nlohmann::json* warning = FindWarning(summary, "disconnected_graph");
  ASSERT_NE(warning, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*warning)["details"]["component_sizes"], nlohmann::json::array({5, 3}));
  EXPECT_EQ((*warning)["images"], nlohmann::json::array({"0005.jpg", "0006.jpg", "0007.jpg"}));
  ASSERT_EQ(summary["components"].size(), 2u);
  // Both solves' observations, their images renumbered into one list.
  const RayTimeObservations rays = Hdf5Reader(dir / "refine.h5").ReadRayTimes("refined");
  EXPECT_EQ(rays.image_names.size(), 8u);
  ASSERT_GT(rays.matches.rows(), 0);
  std::set<bool> components_matched;
  for (Eigen::Index m = 0; m < rays.matches.rows(); ++m) {
    const std::string& a = rays.image_names[rays.observations(rays.matches(m, 0), 0)];
    const std::string& b = rays.image_names[rays.observations(rays.matches(m, 1), 0)];
    EXPECT_NE(a, b);
    EXPECT_EQ(a < "0005.jpg", b < "0005.jpg") << "a match across the components: " << a << b;
    components_matched.insert(a < "0005.jpg");
  }
  EXPECT_EQ(components_matched.size(), 2u);
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
  SceneInputs scene = MakeTwoScenes(false);
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

double MeanRotationErrorDeg(const PoseSet& estimate, const PoseSet& truth) {
  return ComputePoseErrors(estimate, truth, PoseErrorOptions()).mean_rotation_deg;
}

// Runs the export stage on the refine stage's output (its /images when it wrote one): a COLMAP
// text model in dir/refined/ and dir/refined_transforms.json.
// Per-image cameras used to be refused ("the refiner needs shared intrinsics"); with fixed
// intrinsics each image is refined with its own camera, and the cameras are left as they are (no
// /images is written; the export keeps one camera per image).
TEST(RefineStageTest, PerImageCamerasAreRefinedWithTheirOwnIntrinsics) {
  TempDir dir("refine_stage");
  std::vector<CameraIntrinsics> truth;
  const SceneInputs scene = MakePerImageScene(&truth);
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  EXPECT_EQ(refined.size(), 6u);
  EXPECT_EQ(summary["cameras"]["num_cameras"], 6);
  EXPECT_EQ(summary["cameras"]["num_blocks"], 6);
  EXPECT_LT(MeanRotationErrorDeg(refined, scene.ground_truth), 0.01);
  EXPECT_FALSE(Hdf5Reader(dir / "refine.h5").HasImages());
  EXPECT_FALSE(summary.contains("refined_intrinsics"));
  RunExport(dir);
  EXPECT_EQ(ReadColmapModelText(dir / "refined").cameras.size(), 6u);
}

// Self-calibration from focal lengths 1.5 % off (alternately up and down): per_camera writes
// each image's camera refined (closer to the truth than the start) to /cameras and
// /json/refined_intrinsics, and the export writes them (COLMAP: one camera per image;
// transforms.json: per-frame intrinsics); shared writes one camera for every image, exported as
// one COLMAP camera and top-level intrinsics, and warns cameras_shared.
TEST(RefineStageTest, SelfCalibratedCamerasAreWrittenAndExportedPerCamera) {
  std::vector<CameraIntrinsics> truth;
  SceneInputs scene = MakePerImageScene(&truth);
  for (size_t c = 0; c < scene.images.cameras.size(); ++c) {
    const double scale = c % 2 == 0 ? 1.015 : 0.985;
    scene.images.cameras[c].params[kFx] *= scale;
    scene.images.cameras[c].params[kFy] *= scale;
  }
  {
    TempDir dir("refine_stage");
    PoseSet refined;
    const nlohmann::json summary =
        RunRefine(scene, dir, &refined,
                  "{preset: plain, num_threads: 1, trust_region: false, refine_focal: true}");
    EXPECT_EQ(FindWarning(summary, "cameras_shared"), nullptr);
    const ImageSet written = Hdf5Reader(dir / "refine.h5").ReadImages();
    ASSERT_EQ(written.cameras.size(), 6u);
    ASSERT_EQ(summary["refined_intrinsics"].size(), 6u);
    for (int c = 0; c < 6; ++c) {
      EXPECT_EQ(written.images[c].camera_index, c);
      const double start = scene.images.cameras[c].params[kFx] / truth[c].params[kFx] - 1.0;
      const double solved = written.cameras[c].params[kFx] / truth[c].params[kFx] - 1.0;
      EXPECT_LT(std::abs(solved), 0.2 * std::abs(start)) << "camera " << c;
      EXPECT_EQ(summary["refined_intrinsics"][c]["camera"], c);
      EXPECT_EQ(summary["refined_intrinsics"][c]["num_images"], 1);
      EXPECT_EQ(summary["refined_intrinsics"][c]["fx"], written.cameras[c].params[kFx]);
    }
    RunExport(dir);
    const ColmapModel model = ReadColmapModelText(dir / "refined");
    ASSERT_EQ(model.cameras.size(), 6u);
    for (int c = 0; c < 6; ++c) {
      EXPECT_NEAR(IntrinsicsFromColmap(model.cameras.at(c + 1)).params[kFx],
                  written.cameras[c].params[kFx], 1e-9);
    }
    const nlohmann::json transforms = ReadTestJson(dir / "refined_transforms.json");
    EXPECT_FALSE(transforms.contains("fl_x"));
    ASSERT_EQ(transforms["frames"].size(), 6u);
    for (int c = 0; c < 6; ++c) {
      EXPECT_NEAR(transforms["frames"][c]["fl_x"].get<double>(), written.cameras[c].params[kFx],
                  1e-9);
    }
  }
  {
    TempDir dir("refine_stage");
    PoseSet refined;
    const nlohmann::json summary = RunRefine(scene, dir, &refined,
                                             "{preset: plain, num_threads: 1, trust_region: "
                                             "false, refine_focal: true, intrinsics_sharing: "
                                             "shared}");
    const nlohmann::json* warning = FindWarning(summary, "cameras_shared");
    ASSERT_NE(warning, nullptr) << summary["warnings"].dump();
    EXPECT_EQ((*warning)["images"].size(), 6u);
    EXPECT_GT((*warning)["details"]["max_start_disagreement_px"].get<double>(), 1.0);
    const ImageSet written = Hdf5Reader(dir / "refine.h5").ReadImages();
    ASSERT_EQ(written.cameras.size(), 1u);
    for (const ImageInfo& image : written.images) EXPECT_EQ(image.camera_index, 0);
    ASSERT_EQ(summary["refined_intrinsics"].size(), 1u);
    EXPECT_EQ(summary["refined_intrinsics"][0]["num_images"], 6);
    RunExport(dir);
    EXPECT_EQ(ReadColmapModelText(dir / "refined").cameras.size(), 1u);
    const nlohmann::json transforms = ReadTestJson(dir / "refined_transforms.json");
    EXPECT_NEAR(transforms["fl_x"].get<double>(), written.cameras[0].params[kFx], 1e-9);
  }
}

// A prior stated good to 1° / 10 cm (prior.sigma_deg, prior.sigma_m): trusted to place scene B,
// which no pair joins to scene A.
const nlohmann::json kStatedAccuracy = {{"sigma_deg", 1.0}, {"sigma_m", 0.1}};

TEST(RefineStageTest, PosesAGuardrailReturnedAreLeftOutOfTheRefinedExport) {
  TempDir dir("refine_stage");
  // Scene A's prior is 1° off (its solve leaves the tiny trust region and returns the prior);
  // scene B's prior is exact (its solve stays inside and is refined; the stated prior places it).
  const SceneInputs scene = MakeTwoScenes(false, /*exact_prior_for_b=*/true);
  PoseSet refined;
  const nlohmann::json summary =
      RunRefine(scene, dir, &refined, kTinyTrustRegion, Provenance{"test", {}, "", ""}, nullptr,
                kStatedAccuracy);
  const nlohmann::json* returned = FindWarning(summary, "returned_prior");
  ASSERT_NE(returned, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*returned)["images"].size(), 5u);
  EXPECT_EQ(summary["frame_verdicts"]["0000.jpg"]["reason"], "returned_prior");
  EXPECT_EQ(summary["frame_verdicts"]["0005.jpg"]["verdict"], "held_by_prior");
  // Only the returned solve's observations are kept for the export's points.
  const RayTimeObservations rays = Hdf5Reader(dir / "refine.h5").ReadRayTimes("refined");
  EXPECT_EQ(rays.image_names.size(), 8u);
  std::set<std::string> observed;
  for (Eigen::Index o = 0; o < rays.observations.rows(); ++o) {
    observed.insert(rays.image_names.at(rays.observations(o, 0)));
  }
  EXPECT_EQ(observed, (std::set<std::string>{"0005.jpg", "0006.jpg", "0007.jpg"}));
  EXPECT_GT(rays.matches.rows(), 0);
  const nlohmann::json exported = RunExport(dir);
  const nlohmann::json* left_out = FindWarning(exported, "unrefined_not_exported");
  ASSERT_NE(left_out, nullptr) << exported.dump();
  EXPECT_EQ((*left_out)["images"], (*returned)["images"]);
  const ColmapModel model = ReadColmapModel(dir / "refined");
  ASSERT_EQ(model.images.size(), 3u);
  for (const auto& [id, image] : model.images) {
    EXPECT_GE(image.name, "0005.jpg") << "a prior pose exported as refined";
  }
}

// One frame whose keypoints are mirrored (no pose explains its matches: a frame the solve cannot
// place): the inconsistent-pairs warning names it, and the export leaves it out of the refined
// model unless asked to keep it.
TEST(RefineStageTest, AnImageMostOfWhosePairsAreUnexplainedIsNamedAndLeftOutOfTheExport) {
  TempDir dir("refine_stage");
  std::vector<CameraIntrinsics> cameras;
  SceneInputs scene = MakePerImageScene(&cameras);
  auto& keypoints = scene.features[2].keypoints;
  keypoints.col(0).array() = static_cast<float>(cameras[2].width) - keypoints.col(0).array();
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  const nlohmann::json* pairs = FindWarning(summary, "inconsistent_pairs");
  ASSERT_NE(pairs, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*pairs)["images"], nlohmann::json::array({"0002.jpg"}));
  EXPECT_NE((*pairs)["message"].get<std::string>().find("0002.jpg"), std::string::npos);
  EXPECT_EQ(summary["guardrails"]["inconsistent_pairs"]["images_mostly_inconsistent"],
            nlohmann::json::array({2}));
  const nlohmann::json* unexplained = FindWarning(summary, "unexplained_images");
  ASSERT_NE(unexplained, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*unexplained)["images"], nlohmann::json::array({"0002.jpg"}));
  EXPECT_EQ(summary["frame_verdicts"]["0002.jpg"]["verdict"], "doubted");
  EXPECT_EQ(summary["frame_verdicts"]["0002.jpg"]["reason"], "unexplained_pairs");
  EXPECT_EQ(summary["frame_verdicts"]["0001.jpg"]["verdict"], "held");

  const nlohmann::json exported = RunExport(dir);
  const nlohmann::json* left_out = FindWarning(exported, "doubted_not_exported");
  ASSERT_NE(left_out, nullptr) << exported.dump();
  EXPECT_EQ((*left_out)["images"], nlohmann::json::array({"0002.jpg"}));
  EXPECT_EQ((*left_out)["details"]["reasons"]["0002.jpg"], "unexplained_pairs");
  EXPECT_EQ(FindWarning(exported, "unrefined_not_exported"), nullptr);
  ColmapModel model = ReadColmapModelText(dir / "refined");
  ASSERT_EQ(model.images.size(), 5u);
  for (const auto& [id, image] : model.images) EXPECT_NE(image.name, "0002.jpg");
  const nlohmann::json transforms = ReadTestJson(dir / "refined_transforms.json");
  ASSERT_EQ(transforms["frames"].size(), 5u);
  for (const auto& frame : transforms["frames"]) {
    EXPECT_EQ(frame["raytime_verdict"], "held");
    EXPECT_FALSE(frame.contains("raytime_verdict_reason"));
  }
  // Beside the model, every frame's verdict, the left-out one's with its reason.
  const nlohmann::json verdicts = ReadTestJson(dir / "refined/frame_verdicts.json");
  EXPECT_EQ(verdicts["frames"].size(), 6u);
  EXPECT_EQ(verdicts["frames"]["0002.jpg"]["reason"], "unexplained_pairs");

  const nlohmann::json kept =
      RunExport(dir,
                "{poses: [refined], formats: [colmap_text, transforms_json], "
                "leave_out_doubted_images: false}");
  EXPECT_EQ(FindWarning(kept, "doubted_not_exported"), nullptr);
  EXPECT_EQ(ReadColmapModelText(dir / "refined").images.size(), 6u);
  const nlohmann::json kept_transforms = ReadTestJson(dir / "refined_transforms.json");
  for (const auto& frame : kept_transforms["frames"]) {
    if (frame["file_path"].get<std::string>().find("0002.jpg") == std::string::npos) continue;
    EXPECT_EQ(frame["raytime_verdict"], "doubted");
    EXPECT_EQ(frame["raytime_verdict_reason"], "unexplained_pairs");
  }
}

// Issue 30 item 11: a frame held to the others by one pair is a part the matches do not hold (no
// second pair checks it, nothing fixes its distance): without a trusted prior it is doubted
// (loose_parts) and the export leaves it out unless asked to keep it; a prior stated accurate
// enough, that agrees with where the solve put it, keeps it (held_by_prior).
TEST(RefineStageTest, AFrameHeldByOnePairIsNamedAndLeftOutOfTheExport) {
  TempDir dir("refine_stage");
  std::vector<CameraIntrinsics> cameras;
  SceneInputs scene = MakePerImageScene(&cameras);
  scene.matches.erase(
      std::remove_if(scene.matches.begin(), scene.matches.end(),
                     [](const PairMatches& pair) { return pair.image2 == 5 && pair.image1 != 4; }),
      scene.matches.end());
  PoseSet refined;
  const nlohmann::json summary = RunRefine(scene, dir, &refined);
  const nlohmann::json* loose = FindWarning(summary, "loose_parts");
  ASSERT_NE(loose, nullptr) << summary["warnings"].dump();
  EXPECT_EQ((*loose)["images"], nlohmann::json::array({"0005.jpg"}));
  const std::string detail = (*loose)["details"]["0005.jpg"];
  EXPECT_NE(detail.find("by 1 pair(s)"), std::string::npos) << detail;
  EXPECT_NE(detail.find("not trusted"), std::string::npos) << detail;
  EXPECT_EQ(summary["guardrails"]["fired"], nlohmann::json::array({"loose_parts"}));
  EXPECT_EQ(summary["guardrails"]["loose_parts"]["cuts"][0]["pairs_across"], 1);
  EXPECT_EQ(summary["frame_verdicts"]["0005.jpg"]["reason"], "loose_part");

  const nlohmann::json exported = RunExport(dir);
  const nlohmann::json* left_out = FindWarning(exported, "doubted_not_exported");
  ASSERT_NE(left_out, nullptr) << exported.dump();
  EXPECT_EQ((*left_out)["images"], nlohmann::json::array({"0005.jpg"}));
  EXPECT_EQ(ReadColmapModelText(dir / "refined").images.size(), 5u);
  EXPECT_EQ(ReadTestJson(dir / "refined_transforms.json")["frames"].size(), 5u);
  RunExport(dir, "{poses: [refined], formats: [colmap_text], leave_out_doubted_images: false}");
  EXPECT_EQ(ReadColmapModelText(dir / "refined").images.size(), 6u);

  // The prior (1° off) stated good to 2°: the frame is where it says, and kept.
  TempDir stated_dir("refine_stage");
  const nlohmann::json stated =
      RunRefine(scene, stated_dir, &refined, "{preset: plain, num_threads: 1, trust_region: false}",
                Provenance{"test", {}, "", ""}, nullptr, {{"sigma_deg", 2.0}, {"sigma_m", 1.0}});
  EXPECT_EQ(stated["frame_verdicts"]["0005.jpg"]["verdict"], "held_by_prior")
      << stated["frame_verdicts"].dump();
  EXPECT_EQ(FindWarning(stated, "loose_parts"), nullptr);
  const nlohmann::json* by_prior = FindWarning(stated, "held_by_prior");
  ASSERT_NE(by_prior, nullptr) << stated["warnings"].dump();
  EXPECT_EQ((*by_prior)["images"], nlohmann::json::array({"0005.jpg"}));
  RunExport(stated_dir);
  EXPECT_EQ(ReadColmapModelText(stated_dir / "refined").images.size(), 6u);

  // With two pairs (of ~200 matches each) the frame is held.
  TempDir held_dir("refine_stage");
  const SceneInputs held = MakePerImageScene(&cameras);
  const nlohmann::json held_summary = RunRefine(held, held_dir, &refined);
  EXPECT_EQ(FindWarning(held_summary, "loose_parts"), nullptr) << held_summary["warnings"].dump();
  EXPECT_EQ(held_summary["frame_verdicts"]["0005.jpg"]["verdict"], "held");
}

// The smaller components of a match graph in pieces are placed by the prior alone: by one trusted
// (here stated accurate), they are exported and named (held_by_prior); by one nothing vouches for
// (2° off each frame, not probed), or one the prior stage repaired from the matches as coarse (the
// bootstrap's), they are doubted and left out.
TEST(RefineStageTest, ComponentsPlacedByACoarsePriorAreLeftOutOfTheExport) {
  SceneInputs scene = MakeTwoScenes(/*with_lonely_image=*/false);
  uint64_t seed = 1;
  for (auto& [name, pose] : scene.prior.world_from_cam) {
    pose = JitterPoses({scene.ground_truth.world_from_cam.at(name)}, 2.0, 0.1, seed++).front();
  }
  const std::vector<std::string> smaller{"0005.jpg", "0006.jpg", "0007.jpg"};
  for (const std::string prior : {"stated", "given", "repaired"}) {
    SCOPED_TRACE(prior);
    TempDir dir("refine_stage");
    PoseSet refined;
    const nlohmann::json summary =
        RunRefine(scene, dir, &refined, "{preset: plain, num_threads: 1, trust_region: false}",
                  prior == "repaired" ? Provenance{"prior", {{"source", "bootstrap"}}, "", ""}
                                      : Provenance{"test", {}, "", ""},
                  nullptr, prior == "stated" ? kStatedAccuracy : nlohmann::json(nullptr));
    const nlohmann::json* warning = FindWarning(summary, "disconnected_graph");
    ASSERT_NE(warning, nullptr) << summary["warnings"].dump();
    EXPECT_EQ((*warning)["images"], nlohmann::json(smaller));
    const nlohmann::json exported = RunExport(dir);
    const nlohmann::json* left_out = FindWarning(exported, "doubted_not_exported");
    if (prior == "stated") {
      EXPECT_EQ(left_out, nullptr) << exported.dump();
      EXPECT_EQ(summary["frame_verdicts"]["0005.jpg"]["verdict"], "held_by_prior");
      EXPECT_EQ(ReadColmapModelText(dir / "refined").images.size(), 8u);
    } else {
      ASSERT_NE(left_out, nullptr) << exported.dump();
      EXPECT_EQ((*left_out)["images"], nlohmann::json(smaller));
      EXPECT_EQ(summary["frame_verdicts"]["0005.jpg"]["reason"], "disconnected");
      EXPECT_EQ(ReadColmapModelText(dir / "refined").images.size(), 5u);
    }
  }
}

// Format 3dgs of the same run, with the prior beside the refined set: the five images a guardrail
// left unrefined are in no 3dgs export (the refined set lacks them, not_in_every_pose_set), so both
// folders hold the same three images and split, and the points come from the refined solve's ray
// times (each 3D point reprojecting onto its observations in the refined folder).
TEST(RefineStageTest, TrainerExportsShareImagesAcrossPoseSetsAndLeaveOutUnrefinedOnes) {
  TempDir dir("refine_stage");
  SceneInputs scene = MakeTwoScenes(false, /*exact_prior_for_b=*/true);
  scene.images.image_root = dir / "images";
  std::filesystem::create_directories(scene.images.image_root);
  for (const ImageInfo& info : scene.images.images) {
    cv::Mat pixels(info.height, info.width, CV_8UC3, cv::Scalar(40, 80, 120));
    ASSERT_TRUE(cv::imwrite(dir / ("images/" + info.name), pixels));
  }
  PoseSet refined;
  RunRefine(scene, dir, &refined, kTinyTrustRegion, Provenance{"test", {}, "", ""}, nullptr,
            kStatedAccuracy);
  const nlohmann::json summary =
      RunStageInProcess("export", "{poses: [prior, refined], formats: [3dgs]}", dir.path().string(),
                        {{"images", dir / "inputs.h5"},
                         {"poses/prior", dir / "inputs.h5"},
                         {"poses/refined", dir / "refine.h5"}});
  const nlohmann::json* unrefined = FindWarning(summary, "unrefined_not_exported");
  const nlohmann::json* left_out = FindWarning(summary, "not_in_every_pose_set");
  ASSERT_NE(unrefined, nullptr) << summary.dump();
  ASSERT_NE(left_out, nullptr) << summary.dump();
  EXPECT_EQ((*left_out)["images"], (*unrefined)["images"]);
  EXPECT_EQ((*left_out)["details"]["missing_from"]["refined"], (*unrefined)["images"]);
  EXPECT_EQ(FindWarning(summary, "no_initial_points"), nullptr);
  const nlohmann::json& exported = summary["3dgs"];
  EXPECT_EQ(exported["num_images"], 3);
  EXPECT_EQ(exported["num_test"], 1);
  EXPECT_EQ(exported["points_from"], "refined");
  EXPECT_GT(exported["num_points"].get<int>(), 50);
  EXPECT_LT(exported["reprojection_median_px"]["refined"].get<double>(), 0.1);
  for (const std::string set : {"prior", "refined"}) {
    const ColmapModel model = ReadColmapModel(dir / ("3dgs/" + set + "/sparse/0"));
    ASSERT_EQ(model.images.size(), 3u) << set;
    for (const auto& [id, image] : model.images) EXPECT_GE(image.name, "0005.jpg") << set;
    EXPECT_EQ(ReadTextFile(dir / ("3dgs/" + set + "/test.txt")), "0005.jpg\n");
    // The refined set's frames carry their verdicts (scene B: placed by the stated prior).
    const nlohmann::json transforms = ReadTestJson(dir / ("3dgs/" + set + "/transforms.json"));
    for (const auto& frame : transforms["frames"]) {
      if (set == "prior") {
        EXPECT_FALSE(frame.contains("raytime_verdict")) << frame.dump();
      } else {
        EXPECT_EQ(frame["raytime_verdict"], "held_by_prior") << frame.dump();
        EXPECT_EQ(frame["raytime_verdict_reason"], "disconnected") << frame.dump();
      }
    }
  }
}

TEST(RefineStageTest, ExportOfARefinedSetWithNothingRefinedFails) {
  TempDir dir("refine_stage");
  const SceneInputs scene = MakeTwoScenes(false);
  PoseSet refined;
  RunRefine(scene, dir, &refined, kTinyTrustRegion);
  try {
    RunExport(dir);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no pose of 'refined' is left to export"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "refined"));
}

}  // namespace
}  // namespace raytime
