#include "refine/scene.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "core/camera.h"
#include "core/error.h"
#include "core/json_fields.h"
#include "refine/refine.h"

namespace raytime {
namespace {

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

// 1. The prior against the matches' relative poses; refused with the reason.
PriorConventionVerdict CheckConvention(const SceneInput& input) {
  const ImageSet& images = *input.images;
  std::vector<Rigid3> world_from_cam(images.images.size());
  for (size_t i = 0; i < images.images.size(); ++i) {
    const auto pose = input.prior->world_from_cam.find(images.images[i].name);
    if (pose != input.prior->world_from_cam.end()) world_from_cam[i] = pose->second;
  }
  const PriorConventionVerdict convention = CheckPriorConvention(
      world_from_cam, MeasuredRelativePoses(images, *input.features, *input.matches, *input.prior));
  if (convention.checked) {
    const ConventionScore& native = convention.scores.front();
    spdlog::info(fmt::format(
        "refine: the prior as given is {:.2f}° (rotation) / {:.2f}° (baseline direction) "
        "from the matches' relative poses (median over {} pairs, {} with parallax)",
        native.median_rotation_error_deg, native.median_direction_error_deg, convention.num_pairs,
        convention.num_pairs_with_parallax));
  }
  if (convention.refused) {
    throw InputError("refine: " + input.prior_source + ": " +
                     DescribeConventionRefusal(convention, "prior.convention") +
                     " (or refine.check_prior_convention=false to refine it as given)");
  }
  return convention;
}

// Whether the frame's pose is in the refined pose set: a frame no solve refined (no verified
// pair, or a component a self-calibrating run does not solve) is not.
bool InRefinedSet(const FrameVerdict& verdict) {
  return verdict.reason != "unmatched" && verdict.reason != "not_solved";
}

// 5. RefinePoses' output by image name.
void OutputByName(const RefineInput& refine_input, const RefineOutput& output,
                  SceneResult* result) {
  const std::vector<std::string>& names = refine_input.names;
  const RefineSummary& summary = result->summary;
  result->frame_verdicts = nlohmann::json::object();
  result->uncertainty = nlohmann::json::object();
  result->pass_poses = nlohmann::json::object();
  for (size_t k = 0; k < names.size(); ++k) {
    const FrameVerdict& verdict = summary.frame_verdicts[k];
    result->frame_verdicts[names[k]] = verdict;
    if (!InRefinedSet(verdict)) continue;
    result->refined.world_from_cam[names[k]] = output.world_from_cam[k];
    if (verdict.reason == "returned_prior") continue;
    if (k < summary.uncertainty.cameras.size() &&
        std::isfinite(summary.uncertainty.cameras[k].rotation_deg)) {
      result->uncertainty[names[k]] = summary.uncertainty.cameras[k];
    }
  }
  for (const auto& [pass, poses] : output.pass_world_from_cam) {
    for (size_t k = 0; k < names.size() && k < poses.size(); ++k) {
      if (poses[k]) result->pass_poses[pass][names[k]] = PoseJson(*poses[k]);
    }
  }
  AppendRayTimes(refine_input, output.solved_observations, names, &result->ray_times);
  result->diagnostics = {{"images", nlohmann::json::object()},
                         {"pairs", nlohmann::json::array()},
                         {"removed", nlohmann::json::array()}};
  AddDiagnostics(output.diagnostics, summary.pair_removal, names, &result->diagnostics);
}

}  // namespace

EarlierSolution EarlierSolutionOf(const nlohmann::json& pass_poses,
                                  const RayTimeObservations& rays) {
  EarlierSolution earlier;
  for (const auto& [pass, poses] : pass_poses.items()) {
    for (const auto& [name, pose] : poses.items()) {
      earlier.pass_poses[pass][name] = PoseFromJson(pose);
    }
  }
  for (Eigen::Index o = 0; o < rays.observations.rows(); ++o) {
    if (!std::isfinite(rays.ray_times(o))) continue;
    earlier.rays[rays.image_names.at(rays.observations(o, 0))][rays.observations(o, 1)] = {
        rays.pixels.row(o).transpose(), rays.ray_times(o)};
  }
  return earlier;
}

bool RefinedBySolve(const std::string& reason) {
  return reason != "returned_prior" && reason != "unmatched" && reason != "not_solved" &&
         reason != "non_finite";
}

SceneResult RefineScene(const SceneInput& input, const RefineOptions& options) {
  SceneResult result;
  const ImageSet& images = *input.images;
  if (input.features->size() != images.images.size()) {
    throw InputError(input.features_source + ": features for " +
                     std::to_string(input.features->size()) + " images, but the image list has " +
                     std::to_string(images.images.size()));
  }
  // 1. A prior made from the match graph (the bootstrap's) cannot be in another convention.
  if (input.check_prior_convention && !input.prior_rotations_from_matches) {
    result.convention = CheckConvention(input);
  }
  // 2. The images with a prior pose take part; the others are reported (by the stage that made
  // the prior: missing_prior) and counted here.
  for (const ImageInfo& image : images.images) {
    result.num_images_without_prior += !input.prior->Has(image.name);
  }
  std::vector<std::string> names;
  RefineInput refine_input =
      RefineInputOf(images, *input.features, *input.matches, *input.prior, &names);
  if (refine_input.pairs.empty()) {
    throw InputError("refine: no verified image pair joins two images with a prior pose (" +
                     std::to_string(input.matches->size()) + " pairs in " + input.matches_source +
                     "): nothing to refine. Check the matches stage's summary (verified "
                     "pairs, min_num_inliers).");
  }
  refine_input.prior_rotations_from_matches = input.prior_rotations_from_matches;
  refine_input.stated_prior = input.stated_prior;
  // 3.
  if (!input.earlier.empty()) {
    refine_input.warm_start = WarmStartOf(input.earlier, refine_input, names);
  }
  // 4.
  RefineOutput output;
  result.summary = RefinePoses(refine_input, options, &output);
  // 5.
  OutputByName(refine_input, output, &result);
  if (options.SelfCalibrates()) {
    // One solve when self-calibrating: its cameras are refined, the others' as given.
    result.refined_images = WithRefinedCameras(images, output.cameras);
    result.refined_intrinsics = RefinedIntrinsicsJson(*result.refined_images, result.refined);
  }
  return result;
}

}  // namespace raytime
