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
#include "core/graph.h"
#include "core/hdf5_store.h"
#include "core/json_fields.h"
#include "core/warnings.h"
#include "pipelines/stages.h"
#include "refine/camera_blocks.h"
#include "refine/frame_doubt.h"
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
  // Name, and keep out of the refined export, a frame whose correction stands out and whose
  // matches fit worse than the others' (refine/frame_doubt.h: wrong intrinsics, say).
  bool check_frame_doubts = true;
  FrameDoubtOptions frame_doubt;
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
    v("check_frame_doubts", check_frame_doubts,
      "Name, and leave out of the refined export, frames that moved far more than the others and "
      "fit their matches worse (wrong intrinsics, a frame the solve could not place); not for a "
      "prior made from the match graph");
    v("warm_start", warm_start,
      "Start the all-match finish from this work directory's previous refine solution (frames "
      "added or removed since; fewer iterations, a result that depends on that history)");
    frame_doubt.VisitFields(v);  // flat keys: refine.frame_doubt_residual_ratio, ...
    refine.VisitFields(v);       // flat keys: refine.max_matches_per_pair, ...
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

// Images with a prior pose joined by verified pairs, as connected components (largest first,
// image indices ascending). Images with a prior but no verified pair to another such image are
// reported as `unmatched_cameras`: no match constrains them, so they are not refined.
std::vector<std::vector<int>> MatchedComponents(const ImageSet& images,
                                                const std::vector<PairMatches>& matches,
                                                const PoseSet& prior, Warnings* warnings) {
  const int n = static_cast<int>(images.images.size());
  std::vector<std::pair<int, int>> edges;
  std::vector<bool> matched(n, false);
  for (const PairMatches& pair : matches) {
    if (pair.geometry.inlier_matches.rows() == 0 || pair.image1 == pair.image2) continue;
    if (!prior.Has(images.images.at(pair.image1).name) ||
        !prior.Has(images.images.at(pair.image2).name)) {
      continue;
    }
    edges.emplace_back(pair.image1, pair.image2);
    matched[pair.image1] = matched[pair.image2] = true;
  }
  const std::vector<int> labels = ConnectedComponents(n, edges);
  std::vector<std::vector<int>> components;
  Warning unmatched{"unmatched_cameras", "", {}, {}, {}};
  for (int i = 0; i < n; ++i) {
    if (!prior.Has(images.images[i].name)) continue;
    if (!matched[i]) {
      unmatched.images.push_back(images.images[i].name);
      continue;
    }
    if (labels[i] >= static_cast<int>(components.size())) components.resize(labels[i] + 1);
    components[labels[i]].push_back(i);
  }
  // Labels count the unmatched singletons too; keep the matched components in label order.
  components.erase(std::remove_if(components.begin(), components.end(),
                                  [](const std::vector<int>& c) { return c.empty(); }),
                   components.end());
  if (!unmatched.images.empty()) {
    unmatched.message = std::to_string(unmatched.images.size()) +
                        " image(s) with a prior pose have no verified pair with another: they are "
                        "not refined and not in the refined poses";
    warnings->push_back(unmatched);
  }
  return components;
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

// The refiner's input for one component: its images (in image-list order), their cameras (the
// image set's camera list, indexed as there), keypoints and prior poses, and the verified pairs
// between them; `names` receives the images' names.
RefineInput ComponentInput(const ImageSet& images, const std::vector<ImageFeatures>& features,
                           const std::vector<PairMatches>& matches, const PoseSet& prior,
                           const std::vector<int>& component, std::vector<std::string>* names) {
  RefineInput input;
  input.cameras = images.cameras;
  std::vector<int> refine_index(images.images.size(), -1);
  for (int i : component) {
    refine_index[i] = static_cast<int>(names->size());
    names->push_back(images.images[i].name);
    input.camera_index.push_back(images.images[i].camera_index);
    input.prior_world_from_cam.push_back(prior.world_from_cam.at(images.images[i].name));
    input.keypoints.push_back(features[i].keypoints.leftCols<2>().cast<double>());
  }
  for (const PairMatches& pair : matches) {
    const int i = refine_index.at(pair.image1);
    const int j = refine_index.at(pair.image2);
    if (i < 0 || j < 0 || pair.geometry.inlier_matches.rows() == 0) continue;
    input.pairs.push_back({i, j, pair.geometry.inlier_matches});
  }
  return input;
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

// refine/frame_doubt.h's verdict on one returned solve (images as indices into the solve's).
FrameDoubtVerdict FrameDoubtsOf(const RefineInput& input, const RefineOutput& output,
                                const FrameDoubtOptions& options) {
  const SolvedObservations& solved = output.solved_observations;
  const Eigen::Index n = solved.observations.rows();
  Eigen::VectorXi image(n);
  Eigen::Matrix<double, Eigen::Dynamic, 2> pixel(n, 2);
  for (Eigen::Index o = 0; o < n; ++o) {
    image(o) = solved.observations(o, 0);
    pixel.row(o) = input.keypoints[image(o)].row(solved.observations(o, 1));
  }
  std::vector<CameraIntrinsics> intrinsics;
  for (size_t i = 0; i < input.prior_world_from_cam.size(); ++i) {
    intrinsics.push_back(output.cameras.at(input.camera_index[i]));
  }
  return CheckFrameDoubts(input.prior_world_from_cam, output.world_from_cam, intrinsics, image,
                          pixel, solved.ray_times, solved.matches, options);
}

// The frame_doubts warning: the doubted frames by name, with the numbers that doubted them.
void AddFrameDoubtWarning(const FrameDoubtVerdict& verdict, const std::vector<std::string>& names,
                          Warnings* warnings) {
  if (verdict.images.empty()) return;
  Warning warning{"frame_doubts", "", {}, {}, nlohmann::json::object()};
  double worst_change = 0.0, worst_ratio = 0.0;
  for (const int image : verdict.images) {
    warning.images.push_back(names.at(image));
    warning.details["centre_change"][names.at(image)] = verdict.centre_change[image];
    warning.details["residual_ratio"][names.at(image)] = verdict.residual_ratio[image];
    worst_change = std::max(worst_change, verdict.centre_change[image]);
    worst_ratio = std::max(worst_ratio, verdict.residual_ratio[image]);
  }
  warning.details["median_centre_change"] = verdict.median_centre_change;
  warning.details["centre_change_threshold"] = verdict.centre_change_threshold;
  warning.message = fmt::format(
      "{} frame(s) moved far more than the others (up to {:.3g} against a median {:.3g}, length "
      "units of the prior) and fit their matches worse (up to {:.2f}x the median pair's "
      "residual): wrong intrinsics, or a frame the solve could not place: {}",
      verdict.images.size(), worst_change, verdict.median_centre_change, worst_ratio,
      fmt::join(warning.images, ", "));
  warnings->push_back(warning);
}

// A guardrail that returned the prior, or flagged unexplained pairs, is a warning: the poses are
// written (the campaign reports score them), but never as if the solve had succeeded quietly.
void AddGuardrailWarnings(const RefineSummary& summary, const std::vector<std::string>& names,
                          Warnings* warnings) {
  if (summary.guardrails.returned_prior) {
    // The trust region fires when the matches pull the solution far from the prior: most often a
    // prior several degrees off, which the basin configuration is for (§4.8).
    const bool trust_region = summary.guardrails.fired.front() == "trust_region";
    warnings->push_back(
        {"returned_prior",
         "guardrail " + summary.guardrails.fired.front() +
             " fired: the refined poses of these images are the prior's, "
             "unrefined" +
             (trust_region ? std::string("; for a prior more than ~2° off, refine with "
                                         "preset auto (basin solve first, no trust region)")
                           : std::string()),
         names,
         {},
         {{"fired", summary.guardrails.fired}}});
  }
  const InconsistentPairsVerdict& pairs = summary.guardrails.inconsistent_pairs;
  if (pairs.fired) {
    Warning warning{"inconsistent_pairs",
                    std::to_string(pairs.num_inconsistent) + " of " +
                        std::to_string(pairs.num_pairs) +
                        " image pairs keep matches the solution does not explain (wrong pairs, "
                        "e.g. repeated structure, may have pulled it off)",
                    {},
                    {},
                    {{"fraction", pairs.fraction},
                     {"fraction_threshold", pairs.fraction_threshold},
                     {"pair_threshold_px", pairs.pair_threshold_px}}};
    for (const PairResidual& pair : pairs.pairs) {
      warning.pairs.emplace_back(names.at(pair.image1), names.at(pair.image2));
    }
    // Most of these images' pairs are unexplained: a frame the solve did not place, whose pose a
    // trainer should not be given as refined.
    for (const int image : pairs.images_mostly_inconsistent) {
      warning.images.push_back(names.at(image));
    }
    if (!warning.images.empty()) {
      constexpr size_t kNamed = 5;
      std::string named;
      for (size_t i = 0; i < std::min(kNamed, warning.images.size()); ++i) {
        named += (i == 0 ? "" : ", ") + warning.images[i];
      }
      if (warning.images.size() > kNamed) {
        named += " and " + std::to_string(warning.images.size() - kNamed) + " more";
      }
      warning.message +=
          "; most pairs of " + named + " are among them: the pose(s) are likely wrong";
    }
    warnings->push_back(warning);
  }
  // Frames all (or most, three and more) of whose pairs are unexplained, where too few pairs are
  // for the test above to fire: named and left out all the same.
  if (!pairs.fired && !pairs.images_mostly_inconsistent.empty()) {
    Warning warning{
        "unexplained_images", "", {}, {}, {{"pair_threshold_px", pairs.pair_threshold_px}}};
    for (const int image : pairs.images_mostly_inconsistent) {
      warning.images.push_back(names.at(image));
    }
    for (const PairResidual& pair : pairs.pairs) {
      warning.pairs.emplace_back(names.at(pair.image1), names.at(pair.image2));
    }
    warning.message = fmt::format(
        "the solution leaves all or most pairs of {} frame(s) unexplained (above {:.3g} px): "
        "their poses are likely wrong: {}",
        warning.images.size(), pairs.pair_threshold_px, fmt::join(warning.images, ", "));
    warnings->push_back(warning);
  }
  const LoosePartsVerdict& loose = summary.guardrails.loose_parts;
  if (!loose.images.empty()) {
    Warning warning{"loose_parts", "", {}, {}, {{"cuts", nlohmann::json::array()}}};
    for (const int image : loose.images) warning.images.push_back(names.at(image));
    int fewest_left = std::numeric_limits<int>::max();
    for (const LooseCut& cut : loose.cuts) {
      fewest_left = std::min(fewest_left, cut.pairs_across - cut.pairs_removed);
      nlohmann::json named = cut;
      named["images"] = nlohmann::json::array();
      for (const int image : cut.images) named["images"].push_back(names.at(image));
      warning.details["cuts"].push_back(named);
    }
    warning.message = fmt::format(
        "the matches do not hold the placement of {} image(s): they hang on the rest of the match "
        "graph by {} pair(s) or few matches, or the pair removal took most of the pairs that held "
        "them (see details.cuts); a misplaced part looks consistent there. Left out of the "
        "refined export: {}",
        warning.images.size(), fewest_left, fmt::join(warning.images, ", "));
    warnings->push_back(warning);
  }
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
    Solves solves;
    solves.cameras = images.cameras;
    const std::vector<std::vector<int>> components =
        MatchedComponents(images, matches, prior, &solves.warnings);
    if (components.empty()) {
      throw InputError("refine: no verified image pair joins two images with a prior pose (" +
                       std::to_string(matches.size()) + " pairs in " + context.Require("matches") +
                       "): nothing to refine. Check the matches stage's summary (verified "
                       "pairs, min_num_inliers).");
    }
    // A self-calibrated camera must come from one solve: only the largest component then.
    const size_t num_solved = options_.refine.SelfCalibrates() ? 1 : components.size();
    if (components.size() > 1) {
      solves.warnings.push_back(DisconnectedGraphWarning(
          images, components, num_solved, prior_rotations_from_matches, &solves.loose));
    }
    const EarlierSolution earlier =
        options_.warm_start ? ReadEarlierSolution(context, context.OutputPoseSetName("refined"))
                            : EarlierSolution();
    for (size_t c = 0; c < num_solved; ++c) {
      SolveComponent(images, features, matches, prior, components[c], c == 0,
                     prior_rotations_from_matches, earlier, &solves);
    }
    // One verdict over the components: a check that fired anywhere is reported.
    nlohmann::json& result = solves.result;
    result["guardrails"]["fired"] =
        std::vector<std::string>(solves.fired.begin(), solves.fired.end());
    result["guardrails"]["returned_prior"] = solves.returned_prior;
    if (components.size() > 1) result["components"] = solves.component_summaries;
    result["preset"] = options_.preset;
    result["prior_convention"] = convention;
    if (options_.check_frame_doubts) result["frame_doubts"] = solves.frame_doubts;
    result["num_images_without_prior"] = num_without_prior;
    // By image name, over every component whose solve was returned.
    result["uncertainty"]["cameras"] = solves.uncertainty;
    Write(context, images, &solves);
    return result;
  }

 private:
  // What the component solves gather: the refined poses, the first (largest) component's summary
  // and cameras, the verdicts over all, and the images the export leaves out.
  struct Solves {
    PoseSet refined;
    nlohmann::json result;  // the largest component's summary, then the stage's
    nlohmann::json component_summaries = nlohmann::json::array();
    std::set<std::string> fired;
    bool returned_prior = false;
    Warnings warnings;
    // Images whose "refined" pose is the prior's (a guardrail returned it): the export leaves
    // them out of a refined model rather than hand them to a trainer as refined.
    std::vector<std::string> unrefined;
    // Images most of whose pairs a solve that was returned left unexplained: likely wrong poses,
    // which the export leaves out too (leave_out_unexplained_images).
    std::vector<std::string> unexplained;
    // Frames that moved far more than the others and fit worse (FrameDoubtsOf), left out too.
    std::vector<std::string> doubted;
    // Images of parts the matches do not hold to the rest (loose_parts; and, after a prior the
    // bootstrap repaired, the smaller components), left out of the export.
    std::vector<std::string> loose;
    FrameDoubtVerdict frame_doubts;  // of the largest component
    // Per image name, σ of its rotation and centre at the solution (refine/pose_uncertainty.h).
    nlohmann::json uncertainty = nlohmann::json::object();
    // Every solve's fit per image and per pair, by image name (kSolveDiagnosticsJson).
    nlohmann::json diagnostics = {{"images", nlohmann::json::object()},
                                  {"pairs", nlohmann::json::array()},
                                  {"removed", nlohmann::json::array()}};
    std::vector<CameraIntrinsics> cameras;
    // Where each solve put its observations, for the solves whose poses are returned.
    RayTimeObservations rays;
    // The same solves' poses at the end of each pass (kPassPosesJson).
    nlohmann::json pass_poses = nlohmann::json::object();
  };

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

  // disconnected_graph; after a prior repaired from the matches as coarse, the smaller
  // components' images are added to `loose`.
  static Warning DisconnectedGraphWarning(const ImageSet& images,
                                          const std::vector<std::vector<int>>& components,
                                          size_t num_solved, bool prior_rotations_from_matches,
                                          std::vector<std::string>* loose) {
    Warning warning;
    warning.code = "disconnected_graph";
    std::string sizes;
    for (size_t c = 0; c < components.size(); ++c) {
      sizes += (c ? ", " : "") + std::to_string(components[c].size());
      for (int i : components[c]) {
        if (c > 0) warning.images.push_back(images.images[i].name);
      }
    }
    warning.message =
        "the match graph has " + std::to_string(components.size()) + " connected components (" +
        sizes + " images); " +
        (num_solved == 1 ? "only the largest is refined (self-calibration needs one solve); "
                           "the images of the others are not in the refined poses"
                         : "each is refined in its own gauge, anchored to the prior only: "
                           "their relative placement is the prior's");
    // A prior the prior stage found coarse and repaired from the match graph (or the bootstrap's
    // own) places the smaller components by the coarse poses it kept for them (the bootstrap
    // reaches the largest only): nothing holds them to the largest one.
    if (num_solved > 1 && prior_rotations_from_matches) {
      warning.message +=
          ", and that prior was repaired from the matches as coarse: the smaller components' "
          "images are left out of the refined export";
      loose->insert(loose->end(), warning.images.begin(), warning.images.end());
    }
    warning.details = {{"component_sizes", nlohmann::json::array()},
                       {"refined_components", num_solved}};
    for (const auto& component : components) {
      warning.details["component_sizes"].push_back(component.size());
    }
    return warning;
  }

  // One component's solve, its warnings and verdicts into `solves`.
  void SolveComponent(const ImageSet& images, const std::vector<ImageFeatures>& features,
                      const std::vector<PairMatches>& matches, const PoseSet& prior,
                      const std::vector<int>& component, bool largest,
                      bool prior_rotations_from_matches, const EarlierSolution& earlier,
                      Solves* solves) const {
    std::vector<std::string> names;
    RefineInput input = ComponentInput(images, features, matches, prior, component, &names);
    input.prior_rotations_from_matches = prior_rotations_from_matches;
    input.names = names;
    if (!earlier.empty()) input.warm_start = WarmStartOf(earlier, input, names);
    RefineOutput output;
    const RefineSummary summary = RefinePoses(input, options_.refine, &output);
    for (size_t k = 0; k < names.size(); ++k) {
      solves->refined.world_from_cam[names[k]] = output.world_from_cam[k];
    }
    AddGuardrailWarnings(summary, names, &solves->warnings);
    if (summary.cameras.cameras_differ) {
      solves->warnings.push_back(
          {"cameras_shared",
           "intrinsics_sharing 'shared' refined one set of intrinsics for images whose given "
           "cameras differ from it by up to " +
               fmt::format("{:.3g}", summary.cameras.max_start_disagreement_px) +
               " px on the image; their per-image intrinsics were replaced",
           names,
           {},
           {{"num_cameras", summary.cameras.num_cameras},
            {"max_start_disagreement_px", summary.cameras.max_start_disagreement_px},
            {"tolerance_px", kSharedCameraTolerancePx}}});
    }
    AddDiagnostics(output.diagnostics, summary.pair_removal, names, &solves->diagnostics);
    solves->fired.insert(summary.guardrails.fired.begin(), summary.guardrails.fired.end());
    solves->returned_prior = solves->returned_prior || summary.guardrails.returned_prior;
    if (summary.guardrails.returned_prior) {
      solves->unrefined.insert(solves->unrefined.end(), names.begin(), names.end());
    } else {
      for (const int image : summary.guardrails.inconsistent_pairs.images_mostly_inconsistent) {
        solves->unexplained.push_back(names.at(image));
      }
      for (const int image : summary.guardrails.loose_parts.images)
        solves->loose.push_back(names.at(image));
      // A prior made from the match graph (the bootstrap's, or one its repair replaced) is no
      // independent measurement to stand out from: its own errors (a translation-averaging drift
      // at a sequence's ends) doubted correct end frames of entry-P10 at 32°.
      if (options_.check_frame_doubts && !prior_rotations_from_matches) {
        const FrameDoubtVerdict verdict = FrameDoubtsOf(input, output, options_.frame_doubt);
        AddFrameDoubtWarning(verdict, names, &solves->warnings);
        for (const int image : verdict.images) solves->doubted.push_back(names.at(image));
        if (largest) solves->frame_doubts = verdict;
      }
      AppendRayTimes(input, output.solved_observations, names, &solves->rays);
      for (const auto& [pass, poses] : output.pass_world_from_cam) {
        for (size_t k = 0; k < names.size(); ++k) {
          solves->pass_poses[pass][names[k]] = PoseJson(poses[k]);
        }
      }
      for (size_t k = 0; k < names.size() && summary.uncertainty.computed; ++k) {
        solves->uncertainty[names[k]] = summary.uncertainty.cameras[k];
      }
    }
    if (largest) {
      solves->result = summary.ToJson();
      solves->cameras = output.cameras;
    }
    solves->component_summaries.push_back({{"num_images", names.size()},
                                           {"first_image", names.front()},
                                           {"total_iterations", summary.total_iterations},
                                           {"final_cost", summary.final_cost},
                                           {"guardrails_fired", summary.guardrails.fired},
                                           {"returned_prior", summary.guardrails.returned_prior}});
    spdlog::info(
        fmt::format("refine: {} poses, {} iterations in {:.2f} s{}", names.size(),
                    summary.total_iterations, summary.timings.total_seconds,
                    summary.guardrails.returned_prior ? " (guardrail fired: prior returned)" : ""));
  }

  // The refined pose set, its ray times, (self-calibrating) the refined cameras, the summary and
  // the lists of images the export leaves out, in one HDF5 commit.
  void Write(const StageContext& context, const ImageSet& images, Solves* solves) {
    nlohmann::json& result = solves->result;
    const std::string pose_set = context.OutputPoseSetName("refined");
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(pose_set, solves->refined, PoseRole::kRefined, MakeProvenance(*this));
    writer.WriteRayTimes(pose_set, solves->rays);
    result["pose_set"] = pose_set;
    result["num_refined"] = solves->refined.size();
    if (options_.refine.SelfCalibrates()) {
      // One solve when self-calibrating: its cameras are refined, the others' as given.
      const ImageSet refined_images = WithRefinedCameras(images, solves->cameras);
      writer.WriteImages(refined_images);
      result["refined_intrinsics"] = RefinedIntrinsicsJson(refined_images, solves->refined);
      writer.WriteJson("refined_intrinsics", result["refined_intrinsics"]);
    }
    result["warnings"] = WarningsToJson(solves->warnings);
    writer.WriteJson("refine_summary", result);
    writer.WriteJson(kUnrefinedImagesJson, solves->unrefined);
    writer.WriteJson(kUnexplainedImagesJson, solves->unexplained);
    writer.WriteJson(kDoubtedImagesJson, solves->doubted);
    writer.WriteJson(kLooseImagesJson, solves->loose);
    writer.WriteJson(kPoseUncertaintyJson, solves->uncertainty);
    writer.WriteJson(kSolveDiagnosticsJson, solves->diagnostics);
    writer.WriteJson(kPassPosesJson, solves->pass_poses);
    writer.Commit();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateRefineStage() { return std::make_unique<RefineStage>(); }

}  // namespace raytime
