// _raytime.refine: the refine stage's work (refine/scene.h RefineScene) on a match graph built
// elsewhere (pycolmap, hloc, a synthetic scene), given as arrays instead of a work directory's
// HDF5 files. The options are read as the stage reads a pipeline's (pipelines/refine_stage.cc:
// the preset, then the given keys, then one validation), so a key means the same in both.

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>
#include <vector>

#include "core/error.h"
#include "core/features.h"
#include "pipelines/stage.h"
#include "python/arrays.h"
#include "python/bindings.h"
#include "refine/scene.h"

namespace py = pybind11;

namespace raytime::python {
namespace {

using KeypointArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using MatchArray = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;

// Where option messages point: there is no file.
constexpr const char* kOptionsSource = "raytime.refine options";

// A JSON value as the YAML node a pipeline file would hold (no marks: messages name no line).
YAML::Node YamlOf(const nlohmann::json& value) {
  YAML::Node node;
  if (value.is_object()) {
    for (const auto& [key, item] : value.items()) node[key] = YamlOf(item);
  } else if (value.is_array()) {
    for (const auto& item : value) node.push_back(YamlOf(item));
  } else if (value.is_string()) {
    node = value.get<std::string>();
  } else if (!value.is_null()) {
    node = value.dump();
  }
  return node;
}

// The refine stage's options from `options_json` (an object of its keys) over `preset`.
struct StageOptions {
  RefineOptions refine;
  bool check_prior_convention = true;
  std::string preset;
};
StageOptions ConfigureRefine(const std::string& options_json, const std::string& preset) {
  const nlohmann::json given = nlohmann::json::parse(options_json);
  YAML::Node node = YamlOf(given.is_object() ? given : nlohmann::json::object());
  if (!node["preset"]) node["preset"] = preset;
  const std::unique_ptr<Stage> stage = CreateStage("refine");
  stage->Configure(node, kOptionsSource);
  const nlohmann::json configured = stage->OptionsJson();
  StageOptions out;
  OptionsFromJson(configured, out.refine);
  out.check_prior_convention = configured.at("check_prior_convention").get<bool>();
  out.preset = configured.at("preset").get<std::string>();
  return out;
}

// Images, one camera per distinct camera dict, and the prior by name.
void ReadImages(const std::vector<py::dict>& cameras, const std::vector<std::string>& names,
                const std::vector<Rigid3>& poses, PixelConvention convention, ImageSet* images,
                PoseSet* prior) {
  for (size_t i = 0; i < names.size(); ++i) {
    const CameraIntrinsics camera =
        CameraFromDict(cameras.at(i), convention, "cameras[" + std::to_string(i) + "]");
    auto same = std::find(images->cameras.begin(), images->cameras.end(), camera);
    const int index = static_cast<int>(same - images->cameras.begin());
    if (same == images->cameras.end()) images->cameras.push_back(camera);
    images->images.push_back({names[i], camera.width, camera.height, index});
    if (!prior->world_from_cam.emplace(names[i], poses[i]).second) {
      throw InputError("names: '" + names[i] + "' is given twice");
    }
  }
}

// Keypoints (K, 2) in pixels of the caller's convention, as the front end's (OpenCV's) rows.
std::vector<ImageFeatures> ReadKeypoints(const std::vector<KeypointArray>& keypoints,
                                         PixelConvention convention) {
  const double shift = convention == PixelConvention::kColmap ? -0.5 : 0.0;
  std::vector<ImageFeatures> features(keypoints.size());
  for (size_t i = 0; i < keypoints.size(); ++i) {
    const KeypointArray& k = keypoints[i];
    if (k.ndim() != 2 || k.shape(1) != 2) {
      throw InputError("keypoints[" + std::to_string(i) + "]: expected a (K, 2) array of pixels");
    }
    const auto view = k.unchecked<2>();
    features[i].keypoints.setZero(k.shape(0), 4);
    for (py::ssize_t r = 0; r < k.shape(0); ++r) {
      features[i].keypoints(r, 0) = static_cast<float>(view(r, 0) + shift);
      features[i].keypoints(r, 1) = static_cast<float>(view(r, 1) + shift);
      features[i].keypoints(r, 2) = 1.0f;  // a scale the refiner does not read
    }
  }
  return features;
}

// Verified pairs (i, j, (M, 2) keypoint rows), as the front end's: image1 < image2.
std::vector<PairMatches> ReadMatches(const std::vector<std::tuple<int, int, MatchArray>>& matches,
                                     const std::vector<ImageFeatures>& features) {
  std::vector<PairMatches> out;
  const int num_images = static_cast<int>(features.size());
  for (size_t p = 0; p < matches.size(); ++p) {
    const auto& [a, b, rows] = matches[p];
    const std::string where = "matches[" + std::to_string(p) + "]";
    if (a < 0 || b < 0 || a >= num_images || b >= num_images || a == b) {
      throw InputError(where + ": images (" + std::to_string(a) + ", " + std::to_string(b) +
                       ") are not two different indices below " + std::to_string(num_images));
    }
    if (rows.ndim() != 2 || rows.shape(1) != 2) {
      throw InputError(where + ": expected an (M, 2) array of keypoint indices");
    }
    const bool swap = a > b;
    PairMatches pair;
    pair.image1 = swap ? b : a;
    pair.image2 = swap ? a : b;
    pair.geometry.inlier_matches.resize(rows.shape(0), 2);
    const auto view = rows.unchecked<2>();
    for (py::ssize_t r = 0; r < rows.shape(0); ++r) {
      for (int side = 0; side < 2; ++side) {
        const int64_t row = view(r, swap ? 1 - side : side);
        const int image = side == 0 ? pair.image1 : pair.image2;
        if (row < 0 || row >= features[image].keypoints.rows()) {
          throw InputError(where + ": keypoint " + std::to_string(row) + " of image " +
                           std::to_string(image) + " does not exist (it has " +
                           std::to_string(features[image].keypoints.rows()) + ")");
        }
        pair.geometry.inlier_matches(r, side) = static_cast<uint32_t>(row);
      }
    }
    pair.matches = pair.geometry.inlier_matches;
    out.push_back(std::move(pair));
  }
  return out;
}

// The refined poses (the prior's where no solve refined a frame), which were refined, and the
// stage's summary with the frame verdicts and σ as JSON text.
py::tuple Refine(const std::vector<py::dict>& cameras, const PoseArray& poses,
                 const std::vector<KeypointArray>& keypoints,
                 const std::vector<std::tuple<int, int, MatchArray>>& matches,
                 const std::vector<std::string>& names, const std::string& options_json,
                 const std::string& preset, const std::string& pixel_convention) {
  const PixelConvention convention = PixelConventionFromName(pixel_convention);
  const std::vector<Rigid3> prior_poses = PosesFromArray(poses, "poses");
  if (prior_poses.size() != names.size() || cameras.size() != names.size() ||
      keypoints.size() != names.size()) {
    throw InputError("raytime.refine: " + std::to_string(names.size()) + " names, " +
                     std::to_string(prior_poses.size()) + " poses, " +
                     std::to_string(cameras.size()) + " cameras and " +
                     std::to_string(keypoints.size()) + " keypoint arrays: one each per image");
  }
  const StageOptions options = ConfigureRefine(options_json, preset);
  ImageSet images;
  PoseSet prior;
  ReadImages(cameras, names, prior_poses, convention, &images, &prior);
  const std::vector<ImageFeatures> features = ReadKeypoints(keypoints, convention);
  const std::vector<PairMatches> pairs = ReadMatches(matches, features);
  SceneInput input;
  input.images = &images;
  input.features = &features;
  input.matches = &pairs;
  input.prior = &prior;
  input.prior_source = "poses";
  input.features_source = "keypoints";
  input.matches_source = "matches";
  input.check_prior_convention = options.check_prior_convention;
  SceneResult scene;
  RunStoppable([&] { scene = RefineScene(input, options.refine); });

  std::vector<Rigid3> refined_poses = prior_poses;
  std::vector<bool> refined(names.size(), false);
  for (size_t i = 0; i < names.size(); ++i) {
    const auto found = scene.refined.world_from_cam.find(names[i]);
    if (found == scene.refined.world_from_cam.end()) continue;
    // The refined pose set keeps a frame a guardrail returned as the prior, or whose pose is not
    // finite: not refined, so the caller's pose stays.
    const nlohmann::json verdict = scene.frame_verdicts.value(names[i], nlohmann::json::object());
    if (!RefinedBySolve(verdict.value("reason", ""))) continue;
    refined_poses[i] = found->second;
    refined[i] = true;
  }
  nlohmann::json summary = scene.summary.ToJson();
  summary["preset"] = options.preset;
  summary["prior_convention"] = scene.convention;
  const nlohmann::json result = {{"summary", summary},
                                 {"frame_verdicts", scene.frame_verdicts},
                                 {"uncertainty", scene.uncertainty}};
  return py::make_tuple(PosesToArray(refined_poses), refined, result.dump());
}

}  // namespace

void BindRefine(py::module_& m) {
  m.def("refine", &Refine, py::arg("cameras"), py::arg("poses"), py::arg("keypoints"),
        py::arg("matches"), py::arg("names"), py::arg("options_json"), py::arg("preset"),
        py::arg("pixel_convention"),
        "The refine stage on arrays; returns (poses, refined, result JSON text) (raytime.refine "
        "wraps it)");
}

}  // namespace raytime::python
