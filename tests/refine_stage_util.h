// The refine and export stages run on constructed inputs, for the tests of what a run writes and
// exports (tests/refine_stage_test.cc, tests/frame_verdicts_test.cc): a scene's inputs in
// raytime's HDF5 schema, the stages run on them in a temporary folder, and their summaries read.
#pragma once

#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/hdf5_store.h"
#include "pipelines/stage.h"
#include "temp_dir.h"
#include "testing/synthetic_scene.h"
#include "tests/run_stage.h"

namespace raytime {

// The refine stage's inputs.
struct SceneInputs {
  ImageSet images;
  std::vector<ImageFeatures> features;
  std::vector<PairMatches> matches;
  PoseSet ground_truth;
  PoseSet prior;
};

inline std::string Name(int i) {
  char name[16];
  std::snprintf(name, sizeof(name), "%04d.jpg", i);
  return name;
}

// A synthetic scene as the stage's inputs: image i is Name(i) on camera i (the scene's camera
// list), its pairs verified with every match an inlier, the prior the scene's.
inline SceneInputs SceneInputsOf(const SyntheticScene& scene) {
  SceneInputs out;
  out.images.cameras = scene.input.cameras;
  for (size_t k = 0; k < scene.ground_truth.size(); ++k) {
    const int camera = scene.input.camera_index[k];
    const CameraIntrinsics& intrinsics = scene.input.cameras[camera];
    out.images.images.push_back(
        {Name(static_cast<int>(k)), intrinsics.width, intrinsics.height, camera});
    ImageFeatures features;
    features.keypoints.resize(scene.input.keypoints[k].rows(), 4);
    features.keypoints.setZero();
    features.keypoints.leftCols<2>() = scene.input.keypoints[k].cast<float>();
    out.features.push_back(features);
    out.ground_truth.world_from_cam[Name(static_cast<int>(k))] = scene.ground_truth[k];
    out.prior.world_from_cam[Name(static_cast<int>(k))] = scene.input.prior_world_from_cam[k];
  }
  for (const PairMatchIndices& p : scene.input.pairs) {
    PairMatches pair;
    pair.image1 = p.image1;
    pair.image2 = p.image2;
    pair.matches = p.matches;
    pair.geometry.inlier_matches = p.matches;
    out.matches.push_back(pair);
  }
  return out;
}

// Writes the scene's HDF5 inputs and runs the refine stage (by default preset plain, one thread;
// no trust region: its thresholds are object-scale, these scenes are 16 m deep). `prior_repair`
// and `prior_accuracy` are the prior stage's records beside the prior (null: none).
inline nlohmann::json RunRefine(
    const SceneInputs& scene, const TempDir& dir, PoseSet* refined,
    const std::string& options = "{preset: plain, num_threads: 1, trust_region: false}",
    const Provenance& prior_provenance = Provenance{"test", {}, "", ""},
    const nlohmann::json& prior_repair = nullptr, const nlohmann::json& prior_accuracy = nullptr) {
  {
    Hdf5Writer writer(dir / "inputs.h5");
    writer.WriteImages(scene.images);
    writer.WritePoseSet("prior", scene.prior, PoseRole::kPrior, prior_provenance);
    if (!prior_repair.is_null()) writer.WriteJson(kPriorRepairJson, prior_repair);
    if (!prior_accuracy.is_null()) writer.WriteJson("prior_accuracy", prior_accuracy);
    writer.WriteFeatures(scene.features, Provenance{"test", {}, "", ""});
    writer.WriteMatches(scene.matches, Provenance{"test", {}, "", ""});
    writer.Commit();
  }
  std::map<std::string, std::string> artifacts;
  for (const char* artifact : {"images", "features", "matches", "poses/prior"}) {
    artifacts[artifact] = dir / "inputs.h5";
  }
  const nlohmann::json summary =
      RunStageInProcess("refine", options, dir.path().string(), artifacts);
  *refined = Hdf5Reader(dir / "refine.h5").ReadPoseSet("refined");
  return summary;
}

inline const nlohmann::json* FindWarning(const nlohmann::json& summary, const std::string& code) {
  for (const auto& warning : summary["warnings"]) {
    if (warning["code"] == code) return &warning;
  }
  return nullptr;
}

// Runs the export stage on the refine stage's output in `dir`.
inline nlohmann::json RunExport(
    const TempDir& dir,
    const std::string& options = "{poses: [refined], formats: [colmap_text, transforms_json]}") {
  const bool refined_images = Hdf5Reader(dir / "refine.h5").HasImages();
  return RunStageInProcess("export", options, dir.path().string(),
                           {{"images", refined_images ? dir / "refine.h5" : dir / "inputs.h5"},
                            {"poses/refined", dir / "refine.h5"}});
}

inline nlohmann::json ReadTestJson(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

}  // namespace raytime
