// The `refine` stage: the ray-time refiner (refine/, SPEC §3) on the front end's verified matches
// from the pose set "prior" (option `prior`), each image with its own camera's intrinsics. Writes
// the pose set "refined" ("refined@NAME" for a stage id refine@NAME), beside it the solved
// observations and their ray times (/ray_times/<pose set>, for the 3DGS export's initial points;
// only of solves whose poses are returned), the run summary as /json/refine_summary and, when
// self-calibrating, the refined intrinsics per camera (a new /images + /cameras group, so later
// stages such as export use them, and /json/refined_intrinsics).
//
// Named presets are YAML files configs/presets/refine/<name>.yaml (directory RAYTIME_PRESET_DIR
// in the environment, else the source tree's configs/presets); a key given explicitly in the
// pipeline, in --set or on the command line always overrides the preset's, whatever its value.
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <map>
#include <set>

#include "core/camera.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/json_fields.h"
#include "core/warnings.h"
#include "pipelines/stages.h"
#include "refine/prior_convention.h"
#include "refine/refine.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

struct RefineStageOptions {
  // plain | gnc | cap100 | anchored | room-staged | basin | auto (files in the preset directory).
  std::string preset = "gnc";
  // Pose set the solve starts from, e.g. "prior@bootstrap" for a stage prior@bootstrap, so arms
  // seeded differently can share one run.
  std::string prior = "prior";
  // Refuse a prior that the matches' own relative poses say is in another convention (inverted,
  // OpenGL camera axes): refined as given it becomes a wrong answer that looks converged.
  bool check_prior_convention = true;
  // Start the passes on all matches from this stage's solution at its previous run in the work
  // directory (issue 34: a capture that grew or lost frames); the capped passes that decide and
  // the anneal run as without it. Off by default: measured on two grown captures it saves little
  // and makes the result depend on the work directory's history. The chair, 18 -> 24 frames:
  // finish 56 -> 24 iterations (2 s of a 33 s run), poses 0.0002° from a fresh run's. The desk,
  // 153 -> 193 frames: finish 54 -> 68-70 iterations (the solve creeps along a flat valley from
  // either start), the sweep's first frames 0.13° (3.8 σ) from a fresh run's, where a fresh run
  // with a 10^4 x tighter function tolerance moves them 0.06°.
  bool warm_start = false;
  RefineOptions refine;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("preset", preset,
      "Named preset (configs/presets/refine/NAME.yaml) applied before the explicit keys",
      NonEmpty());
    v("prior", prior, "Pose set the solve starts from (e.g. prior, prior@bootstrap)", NonEmpty());
    v("check_prior_convention", check_prior_convention,
      "Refuse a prior that another pose convention (inverted, flipped camera axes) explains far "
      "better than as given, judged by the verified pairs' own relative poses");
    v("warm_start", warm_start,
      "Start the all-match finish from this work directory's previous refine solution (frames "
      "added or removed since; fewer iterations, a result that depends on that history)");
    refine.VisitFields(v);  // flat keys: refine.max_matches_per_pair, ...
  }
  void CheckRelations(const Requirement& require) const { refine.CheckRelations(require); }
};

fs::path PresetDirectory() {
  const char* env = std::getenv("RAYTIME_PRESET_DIR");
  return fs::path(env != nullptr && *env != '\0' ? env : RAYTIME_DEFAULT_PRESET_DIR) / "refine";
}

std::vector<std::string> PresetNames() {
  std::vector<std::string> names;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(PresetDirectory(), error)) {
    if (entry.path().extension() == ".yaml") names.push_back(entry.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

fs::path PresetPath(const std::string& name) {
  const fs::path path = PresetDirectory() / (name + ".yaml");
  if (name.empty() || name.find('/') != std::string::npos || !fs::is_regular_file(path)) {
    const std::vector<std::string> names = PresetNames();
    if (names.empty()) {
      throw InputError("refine.preset '" + name + "': no presets found in " +
                       PresetDirectory().string() + " (set RAYTIME_PRESET_DIR)");
    }
    throw InputError(UnknownKeyMessage("refine.preset", name, names, "preset") + " (in " +
                     PresetDirectory().string() + ")");
  }
  return path;
}

// Whether a prior pose set's rotations were made from the match graph: the bootstrap's own
// poses, a prior stage that took them (`source: bootstrap`), or a prior whose repair replaced
// them (kPriorRepairJson beside it says a mode other than "none").
bool RotationsFromMatches(const Hdf5Reader& reader, const std::string& pose_set,
                          const Provenance& provenance) {
  if (provenance.stage == "bootstrap") return true;
  if (provenance.stage != "prior" || !provenance.options.is_object()) return false;
  if (provenance.options.value("source", "") == "bootstrap") return true;
  if (!reader.HasJson(kPriorRepairJson)) return false;
  const nlohmann::json repair = reader.ReadJson(kPriorRepairJson);
  if (!repair.is_object() || !repair.contains("pose_set") || !repair["pose_set"].is_string() ||
      !repair.contains("mode") || !repair["mode"].is_string()) {
    throw InputError(reader.path() + ": /json/" + kPriorRepairJson +
                     " is not the prior stage's repair record (an object with the strings "
                     "pose_set and mode); run the prior stage again");
  }
  return repair["pose_set"] == pose_set && repair["mode"] != "none";
}

// The refiner's input: every image with a prior pose (in image-list order), their cameras (the
// image set's camera list, indexed as there), keypoints and prior poses, the verified pairs between
// them; `names` receives the images' names.
RefineInput RefineInputOf(const ImageSet& images, const std::vector<ImageFeatures>& features,
                          const std::vector<PairMatches>& matches, const PoseSet& prior,
                          std::vector<std::string>* names) {
  RefineInput input;
  input.cameras = images.cameras;
  std::vector<int> refine_index(images.images.size(), -1);
  for (size_t i = 0; i < images.images.size(); ++i) {
    const ImageInfo& image = images.images[i];
    if (!prior.Has(image.name)) continue;
    refine_index[i] = static_cast<int>(names->size());
    names->push_back(image.name);
    input.camera_index.push_back(image.camera_index);
    input.prior_world_from_cam.push_back(prior.world_from_cam.at(image.name));
    input.keypoints.push_back(features[i].keypoints.leftCols<2>().cast<double>());
  }
  for (const PairMatches& pair : matches) {
    const int i = refine_index.at(pair.image1);
    const int j = refine_index.at(pair.image2);
    if (i < 0 || j < 0 || i == j || pair.geometry.inlier_matches.rows() == 0) continue;
    input.pairs.push_back({i, j, pair.geometry.inlier_matches});
  }
  input.names = *names;
  return input;
}

// The accuracy the prior's maker states (kPriorAccuracyJson beside its pose set), if any.
StatedPriorAccuracy StatedAccuracyOf(const Hdf5Reader& reader) {
  StatedPriorAccuracy stated;
  if (!reader.HasJson(kPriorAccuracyJson)) return stated;
  const nlohmann::json accuracy = reader.ReadJson(kPriorAccuracyJson);
  if (!accuracy.is_object()) {
    throw InputError(reader.path() + ": /json/" + kPriorAccuracyJson +
                     " is not an object {sigma_deg, sigma_m}; run the prior stage again");
  }
  if (accuracy.value("sigma_deg", 0.0) > 0) stated.rotation_deg = accuracy["sigma_deg"];
  if (accuracy.value("sigma_m", 0.0) > 0) stated.centre = accuracy["sigma_m"];
  return stated;
}

// `images` with the refined cameras (indexed as images.cameras); cameras that became equal (the
// one shared set written to every camera its images used) are one camera, in the order of their
// first occurrence, so a COLMAP model has one camera per distinct camera.
ImageSet WithRefinedCameras(const ImageSet& images, const std::vector<CameraIntrinsics>& refined) {
  ImageSet out = images;
  out.cameras.clear();
  std::vector<int> new_index(refined.size());
  for (size_t c = 0; c < refined.size(); ++c) {
    const auto same = std::find(out.cameras.begin(), out.cameras.end(), refined[c]);
    new_index[c] = static_cast<int>(same - out.cameras.begin());
    if (same == out.cameras.end()) out.cameras.push_back(refined[c]);
  }
  for (ImageInfo& image : out.images) image.camera_index = new_index[image.camera_index];
  return out;
}

// Per camera of `images` that a refined image uses: its index, how many refined images use it and
// its intrinsics (OpenCV pixel convention).
nlohmann::json RefinedIntrinsicsJson(const ImageSet& images, const PoseSet& refined) {
  std::vector<int> count(images.cameras.size(), 0);
  for (const ImageInfo& image : images.images) {
    if (refined.Has(image.name)) ++count[image.camera_index];
  }
  nlohmann::json out = nlohmann::json::array();
  for (size_t c = 0; c < images.cameras.size(); ++c) {
    if (count[c] == 0) continue;
    const auto& p = images.cameras[c].params;
    out.push_back({{"camera", c},
                   {"num_images", count[c]},
                   {"fx", p[kFx]},
                   {"fy", p[kFy]},
                   {"cx", p[kCx]},
                   {"cy", p[kCy]},
                   {"k1", p[kK1]},
                   {"k2", p[kK2]},
                   {"p1", p[kP1]},
                   {"p2", p[kP2]}});
  }
  return out;
}

// Adds one solve's fit per image and per pair to `out` (kSolveDiagnosticsJson), by image name.
void AddDiagnostics(const SolveDiagnostics& diagnostics, const PairRemovalSummary& removal,
                    const std::vector<std::string>& names, nlohmann::json* out) {
  for (const PairResidual& pair : removal.removed) {
    (*out)["removed"].push_back({names.at(pair.image1), names.at(pair.image2), pair.num_matches,
                                 NullIfNonFinite(pair.median_px)});
  }
  std::vector<int> num_pairs(names.size(), 0), num_matches(names.size(), 0);
  for (const PairResidual& pair : diagnostics.pairs) {
    for (const int image : {pair.image1, pair.image2}) {
      ++num_pairs[image];
      num_matches[image] += pair.num_matches;
    }
    (*out)["pairs"].push_back({names.at(pair.image1), names.at(pair.image2), pair.num_matches,
                               NullIfNonFinite(pair.median_px)});
  }
  for (size_t i = 0; i < names.size() && i < diagnostics.image_residual_median_px.size(); ++i) {
    (*out)["images"][names[i]] = {
        {"residual_median_px", NullIfNonFinite(diagnostics.image_residual_median_px[i])},
        {"num_pairs", num_pairs[i]},
        {"num_matches", num_matches[i]}};
  }
}

// Appends one solve's observations, ray times and used matches to `rays` (its images by name).
void AppendRayTimes(const RefineInput& input, const SolvedObservations& solved,
                    const std::vector<std::string>& names, RayTimeObservations* rays) {
  const auto image_offset = static_cast<uint32_t>(rays->image_names.size());
  rays->image_names.insert(rays->image_names.end(), names.begin(), names.end());
  const Eigen::Index start = rays->observations.rows();
  const Eigen::Index n = solved.observations.rows();
  rays->observations.conservativeResize(start + n, 2);
  rays->pixels.conservativeResize(start + n, 2);
  rays->ray_times.conservativeResize(start + n);
  for (Eigen::Index o = 0; o < n; ++o) {
    const int image = solved.observations(o, 0);
    const int keypoint = solved.observations(o, 1);
    rays->observations.row(start + o) << image_offset + static_cast<uint32_t>(image),
        static_cast<uint32_t>(keypoint);
    rays->pixels.row(start + o) = input.keypoints[image].row(keypoint);
    rays->ray_times(start + o) = solved.ray_times(o);
  }
  const Eigen::Index match_start = rays->matches.rows();
  rays->matches.conservativeResize(match_start + solved.matches.rows(), 2);
  for (Eigen::Index m = 0; m < solved.matches.rows(); ++m) {
    rays->matches.row(match_start + m) << static_cast<uint32_t>(start + solved.matches(m, 0)),
        static_cast<uint32_t>(start + solved.matches(m, 1));
  }
}

// JSON document beside a refined pose set: per pass name that an earlier run's solution may start
// (RefineWarmStart), per image name, its pose at the end of that pass: [qw, qx, qy, qz, x, y, z]
// (rotation world_from_cam, camera centre). Written by refine, read by its next run.
constexpr const char* kPassPosesJson = "pass_poses";

// This stage's solution at its previous run in the work directory, by image name.
struct EarlierSolution {
  std::map<std::string, std::map<std::string, Rigid3>> pass_poses;
  // Per image name, per keypoint row: its pixel (to check the keypoint is the same) and ray time.
  std::map<std::string, std::map<uint32_t, std::pair<Eigen::Vector2d, double>>> rays;
  bool empty() const { return pass_poses.empty(); }
};

nlohmann::json PoseJson(const Rigid3& pose) {
  const Eigen::Quaterniond& q = pose.rotation;
  const Eigen::Vector3d& c = pose.translation;
  return {q.w(), q.x(), q.y(), q.z(), c.x(), c.y(), c.z()};
}

Rigid3 PoseFromJson(const nlohmann::json& value) {
  const std::vector<double> v = value.get<std::vector<double>>();
  if (v.size() != 7) throw InputError("a pose of " + std::to_string(v.size()) + " numbers, not 7");
  Rigid3 pose;
  pose.rotation = Eigen::Quaterniond(v[0], v[1], v[2], v[3]).normalized();
  pose.translation = Eigen::Vector3d(v[4], v[5], v[6]);
  return pose;
}

// The earlier solution in the stage's previous output; empty when it has none (an older output, or
// every solve returned the prior). Unreadable: empty, and the log says why.
EarlierSolution ReadEarlierSolution(const StageContext& context, const std::string& pose_set) {
  EarlierSolution earlier;
  const bool read = context.ReadPreviousOutput(
      [&](const Hdf5Reader& reader) {
        if (!reader.HasJson(kPassPosesJson) || !reader.HasRayTimes(pose_set)) return;
        const nlohmann::json pass_poses = reader.ReadJson(kPassPosesJson);
        for (const auto& [pass, poses] : pass_poses.items()) {
          for (const auto& [name, pose] : poses.items()) {
            earlier.pass_poses[pass][name] = PoseFromJson(pose);
          }
        }
        const RayTimeObservations rays = reader.ReadRayTimes(pose_set);
        for (Eigen::Index o = 0; o < rays.observations.rows(); ++o) {
          if (!std::isfinite(rays.ray_times(o))) continue;
          earlier.rays[rays.image_names.at(rays.observations(o, 0))][rays.observations(o, 1)] = {
              rays.pixels.row(o).transpose(), rays.ray_times(o)};
        }
      },
      "starting from the prior");
  return read ? earlier : EarlierSolution();
}

// The earlier solution as the start of one component's solve (its images by name; a ray time
// only where the keypoint row still holds the same pixel).
RefineWarmStart WarmStartOf(const EarlierSolution& earlier, const RefineInput& input,
                            const std::vector<std::string>& names) {
  RefineWarmStart warm;
  for (const auto& [pass, poses] : earlier.pass_poses) {
    std::vector<std::optional<Rigid3>>& start = warm.world_from_cam[pass];
    start.resize(names.size());
    for (size_t i = 0; i < names.size(); ++i) {
      const auto found = poses.find(names[i]);
      if (found != poses.end()) start[i] = found->second;
    }
  }
  for (size_t i = 0; i < names.size(); ++i) {
    const auto image = earlier.rays.find(names[i]);
    if (image == earlier.rays.end()) continue;
    for (const auto& [keypoint, ray] : image->second) {
      if (keypoint >= input.keypoints[i].rows() ||
          input.keypoints[i].row(keypoint).transpose() != ray.first) {
        continue;
      }
      warm.ray_times[WarmRayTimeKey(static_cast<int>(i), static_cast<int>(keypoint))] = ray.second;
    }
  }
  return warm;
}

// The verified pairs' relative poses from their essential matrices (pairs of images that both have
// a prior pose), for the convention check; at most kParallaxSamples inliers per pair measure its
// parallax.
std::vector<MeasuredRelativePose> MeasuredRelativePoses(const ImageSet& images,
                                                        const std::vector<ImageFeatures>& features,
                                                        const std::vector<PairMatches>& matches,
                                                        const PoseSet& prior) {
  constexpr Eigen::Index kParallaxSamples = 200;
  const auto unit_ray = [&](int image, uint32_t keypoint) {
    const double* k = images.cameras.at(images.images.at(image).camera_index).params.data();
    const double observed[2] = {features.at(image).keypoints(keypoint, 0),
                                features.at(image).keypoints(keypoint, 1)};
    Eigen::Vector3d ray;
    ObservedPixelToUnitRay(k, observed, ray.data());
    return ray;
  };
  std::vector<MeasuredRelativePose> out;
  for (const PairMatches& pair : matches) {
    const auto& inliers = pair.geometry.inlier_matches;
    if (pair.geometry.config != TwoViewConfig::kCalibrated || inliers.rows() == 0 ||
        !prior.Has(images.images.at(pair.image1).name) ||
        !prior.Has(images.images.at(pair.image2).name)) {
      continue;
    }
    MeasuredRelativePose measured;
    measured.image1 = pair.image1;
    measured.image2 = pair.image2;
    measured.cam2_from_cam1_rotation = pair.geometry.cam2_from_cam1.RotationMatrix();
    measured.cam2_from_cam1_direction = pair.geometry.cam2_from_cam1.translation.normalized();
    const Eigen::Index step = std::max<Eigen::Index>(1, inliers.rows() / kParallaxSamples);
    const Eigen::Index samples = (inliers.rows() + step - 1) / step;
    Eigen::Matrix<double, Eigen::Dynamic, 3> rays1(samples, 3), rays2(samples, 3);
    for (Eigen::Index s = 0; s < samples; ++s) {
      rays1.row(s) = unit_ray(pair.image1, inliers(s * step, 0)).transpose();
      rays2.row(s) = unit_ray(pair.image2, inliers(s * step, 1)).transpose();
    }
    measured.median_parallax_deg =
        MedianParallaxDeg(measured.cam2_from_cam1_rotation, rays1, rays2);
    out.push_back(measured);
  }
  return out;
}

class RefineStage : public StageWithOptions<RefineStageOptions> {
 public:
  std::string type() const override { return "refine"; }
  std::string description() const override {
    return "Refine the prior's poses with the ray-time GNC solver (preset " + options_.preset + ")";
  }

  // The preset's values, under the keys the pipeline gives explicitly (StageWithOptions).
  void ApplyPreset(const YAML::Node& node, const std::string& path) override {
    if (node && node.IsMap() && node["preset"]) {
      ReadYamlField(node["preset"], options_.preset, path, "preset");
    }
    const fs::path preset_path = PresetPath(options_.preset);
    const YAML::Node preset = LoadYamlFile(preset_path.string());
    ApplyYaml(preset, options_.refine, preset_path.string(),
              "refine preset '" + options_.preset + "'");
  }

  std::vector<std::string> Inputs() const override {
    return {kArtifactImages, "features", "matches", PoseArtifact(options_.prior)};
  }
  std::vector<std::string> ExternalFiles() const override {
    return {PresetPath(options_.preset).string()};
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::vector<ImageFeatures> features =
        Hdf5Reader(context.Require("features")).ReadFeatures();
    const std::vector<PairMatches> matches = Hdf5Reader(context.Require("matches")).ReadMatches();
    Provenance prior_provenance;
    const Hdf5Reader prior_reader(context.Require(PoseArtifact(options_.prior)));
    const PoseSet prior = prior_reader.ReadPoseSet(options_.prior, nullptr, &prior_provenance);
    const bool prior_rotations_from_matches =
        RotationsFromMatches(prior_reader, options_.prior, prior_provenance);
    if (features.size() != images.images.size()) {
      throw InputError(context.Require("features") + ": features for " +
                       std::to_string(features.size()) + " images, but the image list has " +
                       std::to_string(images.images.size()));
    }
    // A prior in another convention is refused before any solve (issue 30); a prior made from
    // the match graph (the bootstrap's) cannot be in one.
    const PriorConventionVerdict convention =
        options_.check_prior_convention && !prior_rotations_from_matches
            ? CheckConvention(images, features, matches, prior, context)
            : PriorConventionVerdict();

    // The images with a prior pose take part; the others are reported (by the stage that made
    // the prior: missing_prior) and counted here.
    size_t num_without_prior = 0;
    for (const ImageInfo& image : images.images) num_without_prior += !prior.Has(image.name);
    std::vector<std::string> names;
    RefineInput input = RefineInputOf(images, features, matches, prior, &names);
    if (input.pairs.empty()) {
      throw InputError("refine: no verified image pair joins two images with a prior pose (" +
                       std::to_string(matches.size()) + " pairs in " + context.Require("matches") +
                       "): nothing to refine. Check the matches stage's summary (verified "
                       "pairs, min_num_inliers).");
    }
    input.prior_rotations_from_matches = prior_rotations_from_matches;
    input.stated_prior = StatedAccuracyOf(prior_reader);
    if (options_.warm_start) {
      const EarlierSolution earlier =
          ReadEarlierSolution(context, context.OutputPoseSetName("refined"));
      if (!earlier.empty()) input.warm_start = WarmStartOf(earlier, input, names);
    }
    RefineOutput output;
    const RefineSummary summary = RefinePoses(input, options_.refine, &output);
    nlohmann::json result = summary.ToJson();
    result["preset"] = options_.preset;
    result["prior_convention"] = convention;
    result["num_images_without_prior"] = num_without_prior;
    Write(context, images, input, summary, output, &result);
    return result;
  }

 private:
  // The prior against the matches' relative poses (prior_convention.h); refused with the reason.
  PriorConventionVerdict CheckConvention(const ImageSet& images,
                                         const std::vector<ImageFeatures>& features,
                                         const std::vector<PairMatches>& matches,
                                         const PoseSet& prior, const StageContext& context) const {
    std::vector<Rigid3> world_from_cam(images.images.size());
    for (size_t i = 0; i < images.images.size(); ++i) {
      const auto pose = prior.world_from_cam.find(images.images[i].name);
      if (pose != prior.world_from_cam.end()) world_from_cam[i] = pose->second;
    }
    const PriorConventionVerdict convention = CheckPriorConvention(
        world_from_cam, MeasuredRelativePoses(images, features, matches, prior));
    if (convention.checked) {
      const ConventionScore& native = convention.scores.front();
      spdlog::info(fmt::format(
          "refine: the prior as given is {:.2f}° (rotation) / {:.2f}° (baseline direction) "
          "from the matches' relative poses (median over {} pairs, {} with parallax)",
          native.median_rotation_error_deg, native.median_direction_error_deg, convention.num_pairs,
          convention.num_pairs_with_parallax));
    }
    if (convention.refused) {
      throw InputError("refine: pose set '" + options_.prior + "' of " +
                       context.Require(PoseArtifact(options_.prior)) + ": " +
                       DescribeConventionRefusal(convention, "prior.convention") +
                       " (or refine.check_prior_convention=false to refine it as given)");
    }
    return convention;
  }

  // Whether the frame's pose is in the refined pose set: a frame no solve refined (no verified
  // pair, or a component a self-calibrating run does not solve) is not.
  static bool InRefinedSet(const FrameVerdict& verdict) {
    return verdict.reason != "unmatched" && verdict.reason != "not_solved";
  }

  // The refined pose set, its ray times, (self-calibrating) the refined cameras, the frame
  // verdicts, the uncertainty and the diagnostics by image name, in one HDF5 commit; the summary's
  // per-image lists by name.
  void Write(const StageContext& context, const ImageSet& images, const RefineInput& input,
             const RefineSummary& summary, const RefineOutput& output, nlohmann::json* result) {
    const std::vector<std::string>& names = input.names;
    PoseSet refined;
    nlohmann::json verdicts = nlohmann::json::object();
    nlohmann::json uncertainty = nlohmann::json::object();
    nlohmann::json pass_poses = nlohmann::json::object();
    for (size_t k = 0; k < names.size(); ++k) {
      const FrameVerdict& verdict = summary.frame_verdicts[k];
      verdicts[names[k]] = verdict;
      if (!InRefinedSet(verdict)) continue;
      refined.world_from_cam[names[k]] = output.world_from_cam[k];
      if (verdict.reason == "returned_prior") continue;
      if (k < summary.uncertainty.cameras.size() &&
          std::isfinite(summary.uncertainty.cameras[k].rotation_deg)) {
        uncertainty[names[k]] = summary.uncertainty.cameras[k];
      }
    }
    for (const auto& [pass, poses] : output.pass_world_from_cam) {
      for (size_t k = 0; k < names.size() && k < poses.size(); ++k) {
        if (poses[k]) pass_poses[pass][names[k]] = PoseJson(*poses[k]);
      }
    }
    RayTimeObservations rays;
    AppendRayTimes(input, output.solved_observations, names, &rays);
    nlohmann::json diagnostics = {{"images", nlohmann::json::object()},
                                  {"pairs", nlohmann::json::array()},
                                  {"removed", nlohmann::json::array()}};
    AddDiagnostics(output.diagnostics, summary.pair_removal, names, &diagnostics);

    const std::string pose_set = context.OutputPoseSetName("refined");
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(pose_set, refined, PoseRole::kRefined, MakeProvenance(*this));
    writer.WriteRayTimes(pose_set, rays);
    (*result)["pose_set"] = pose_set;
    (*result)["num_refined"] = refined.size();
    (*result)["frame_verdicts"] = verdicts;
    (*result)["uncertainty"]["cameras"] = uncertainty;
    if (options_.refine.SelfCalibrates()) {
      // One solve when self-calibrating: its cameras are refined, the others' as given.
      const ImageSet refined_images = WithRefinedCameras(images, output.cameras);
      writer.WriteImages(refined_images);
      (*result)["refined_intrinsics"] = RefinedIntrinsicsJson(refined_images, refined);
      writer.WriteJson("refined_intrinsics", (*result)["refined_intrinsics"]);
    }
    writer.WriteJson("refine_summary", *result);
    writer.WriteJson(kFrameVerdictsJson, verdicts);
    writer.WriteJson(kPoseUncertaintyJson, uncertainty);
    writer.WriteJson(kSolveDiagnosticsJson, diagnostics);
    writer.WriteJson(kPassPosesJson, pass_poses);
    writer.Commit();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateRefineStage() { return std::make_unique<RefineStage>(); }

}  // namespace raytime
