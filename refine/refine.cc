// RefinePoses: the match graph's components, each solved on its own
// (refine/recipes/connected_solve.h: intrinsics blocks -> recipe of passes -> uncertainty ->
// guardrails -> frame checks), then one verdict per frame from all the evidence
// (refine/checks/frame_verdicts.h) and the warnings that name what is not simply held
// (refine/checks/refine_warnings.h).
#include "refine/refine.h"

#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/options.h"
#include "core/statistics.h"
#include "core/timing.h"
#include "refine/checks/refine_warnings.h"
#include "refine/recipes/components.h"
#include "refine/recipes/connected_solve.h"

namespace raytime {
namespace {

void ValidateInput(const RefineInput& input) {
  const size_t n = input.prior_world_from_cam.size();
  if (input.keypoints.size() != n) {
    throw InputError("refine: " + std::to_string(n) + " prior poses but keypoints for " +
                     std::to_string(input.keypoints.size()) + " images");
  }
  if (input.camera_index.size() != n) {
    throw InputError("refine: " + std::to_string(n) + " prior poses but camera indices for " +
                     std::to_string(input.camera_index.size()) + " images");
  }
  for (size_t i = 0; i < n; ++i) {
    const int camera = input.camera_index[i];
    if (camera < 0 || camera >= static_cast<int>(input.cameras.size())) {
      throw InputError("refine: image " + std::to_string(i) + " has camera index " +
                       std::to_string(camera) + " but there are " +
                       std::to_string(input.cameras.size()) + " cameras");
    }
    const auto& p = input.cameras[camera].params;
    if (!(p[kFx] > 0) || !(p[kFy] > 0)) {
      throw InputError("refine: camera " + std::to_string(camera) +
                       " needs positive focal lengths, got fx = " + std::to_string(p[kFx]) +
                       ", fy = " + std::to_string(p[kFy]));
    }
  }
}

// Before any solve: every image at its prior, the input's cameras, nothing solved.
RefineOutput UnsolvedOutput(const RefineInput& input) {
  RefineOutput output;
  output.world_from_cam = input.prior_world_from_cam;
  for (Rigid3& pose : output.world_from_cam) pose.rotation.normalize();
  output.solved_world_from_cam = output.world_from_cam;
  output.cameras = output.solved_cameras = input.cameras;
  output.diagnostics.image_residual_median_px.assign(input.prior_world_from_cam.size(),
                                                     std::numeric_limits<double>::quiet_NaN());
  return output;
}

// Why the images of a component or outside every component were not refined.
void NotRefined(const std::vector<int>& images, const std::string& reason,
                const std::string& detail, FrameEvidence* evidence) {
  for (const int image : images) evidence->findings.push_back({image, reason, detail});
}

// A smaller component's summary into the whole run's (the largest's): its guardrails fired, its
// removed pairs, its frames' uncertainty and intrinsics tests.
void AddComponent(const RefineSummary& part, const std::vector<int>& images,
                  RefineSummary* summary) {
  for (const std::string& check : part.guardrails.fired) {
    if (std::find(summary->guardrails.fired.begin(), summary->guardrails.fired.end(), check) ==
        summary->guardrails.fired.end()) {
      summary->guardrails.fired.push_back(check);
    }
  }
  summary->guardrails.returned_prior =
      summary->guardrails.returned_prior || part.guardrails.returned_prior;
  summary->pair_removal.removed.insert(summary->pair_removal.removed.end(),
                                       part.pair_removal.removed.begin(),
                                       part.pair_removal.removed.end());
  for (const int image : images) {
    summary->uncertainty.cameras.at(image) = part.uncertainty.cameras.at(image);
  }
  summary->frame_intrinsics.insert(summary->frame_intrinsics.end(), part.frame_intrinsics.begin(),
                                   part.frame_intrinsics.end());
}

// Whether the poses' centres all coincide (to 1e-9 of their distance from the origin): a prior
// from a gyro, or any rotation-only one. Such a prior has no baseline and no scale; refined as
// given, the solve found the right shape but the position prior and the gauge fit held it at the
// one point (the sample from such a prior: every camera within 1e-7 m, "accepted").
bool CentresCoincide(const std::vector<Rigid3>& poses) {
  if (poses.size() < 2) return false;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : poses) centroid += pose.translation / static_cast<double>(poses.size());
  double spread = 0.0;
  for (const Rigid3& pose : poses) spread = std::max(spread, (pose.translation - centroid).norm());
  return spread <= 1e-9 * centroid.norm();
}

// A prior without baseline gets its centres from the matches: a first solve from it finds the
// shape at the scale the coinciding centres leave, and its centres, scaled to a median ray time
// of 1, become the prior's (its rotations kept) for the solve that is returned. The result's
// scale is arbitrary, as the prior's was. False when the first solve gives no scale.
bool SeedCentresFromMatches(const RefineOptions& options, RefineInput* part) {
  RefineOutput first;
  std::vector<FrameFinding> ignored;
  spdlog::info(
      "refine: the prior's centres all coincide (no baseline): a first solve takes the "
      "centres from the matches");
  RefineOptions shape_only = options;  // its frames are judged in the solve that is returned
  shape_only.check_frame_doubts = false;
  shape_only.check_frame_intrinsics = false;
  shape_only.uncertainty_max_cameras = 0;
  SolveConnected(*part, shape_only, &first, &ignored);
  std::vector<double> ray_times;
  for (Eigen::Index o = 0; o < first.solved_observations.ray_times.size(); ++o) {
    const double t = first.solved_observations.ray_times(o);
    if (std::isfinite(t) && t > 0) ray_times.push_back(t);
  }
  const double depth = Median(ray_times, 0.0);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : first.solved_world_from_cam) {
    centroid += pose.translation / static_cast<double>(first.solved_world_from_cam.size());
  }
  if (!(depth > 0) || !std::isfinite(depth)) return false;
  for (size_t k = 0; k < part->prior_world_from_cam.size(); ++k) {
    part->prior_world_from_cam[k].translation =
        (first.solved_world_from_cam[k].translation - centroid) / depth;
  }
  return true;
}

// One component's solve, its output merged into *output and its evidence into *evidence; its
// summary in the input's indices.
RefineSummary SolveComponent(const RefineInput& input, const RefineOptions& options,
                             const std::vector<int>& images, bool largest, RefineOutput* output,
                             FrameEvidence* evidence, Warnings* warnings) {
  RefineInput part = ComponentInput(input, images);
  if (CentresCoincide(part.prior_world_from_cam) && SeedCentresFromMatches(options, &part)) {
    std::vector<std::string> names;
    for (size_t k = 0; k < images.size(); ++k) {
      evidence->prior[images[k]].translation = part.prior_world_from_cam[k].translation;
      names.push_back(input.Label(images[k]));
    }
    warnings->push_back(
        {"prior_without_baseline",
         "the prior's centres all coincide (a rotation-only prior): the centres were taken from "
         "the matches (a first solve), at an arbitrary scale (median ray time 1); the prior's "
         "rotations are kept",
         names,
         {},
         nlohmann::json::object()});
  }
  RefineOutput part_output;
  std::vector<FrameFinding> findings;
  RefineSummary summary = SolveConnected(part, options, &part_output, &findings);
  const int n = static_cast<int>(input.prior_world_from_cam.size());
  ToInputIndices(images, n, &summary);
  MergeComponentOutput(images, part_output, largest, !summary.guardrails.returned_prior, output);
  if (summary.guardrails.returned_prior) {
    NotRefined(images, "returned_prior",
               fmt::format("guardrail {} of its solve fired: its pose is the prior's, not refined",
                           summary.guardrails.fired.front()),
               evidence);
    return summary;
  }
  for (FrameFinding finding : findings) {
    finding.image = images.at(finding.image);
    evidence->findings.push_back(finding);
  }
  evidence->loose_cuts.insert(evidence->loose_cuts.end(),
                              summary.guardrails.loose_parts.cuts.begin(),
                              summary.guardrails.loose_parts.cuts.end());
  return summary;
}

void LogFrameVerdicts(const RefineInput& input, const RefineSummary& summary) {
  const PriorTrust& trust = summary.prior_trust;
  spdlog::info(fmt::format(
      "refine: prior {} ({}): {}", trust.trusted ? "trusted" : "not trusted", trust.source,
      trust.num_reference_frames > 0
          ? fmt::format("the {} frames the matches hold agree with it to {:.3g}° / {:.3g} "
                        "(median)",
                        trust.num_reference_frames, trust.median_rotation_deg, trust.median_centre)
          : std::string("no frame of the largest component is held by its matches")));
  std::map<std::string, std::vector<std::string>> by_verdict;
  for (size_t i = 0; i < summary.frame_verdicts.size(); ++i) {
    const FrameVerdict& verdict = summary.frame_verdicts[i];
    if (verdict.verdict == kVerdictHeld) continue;
    by_verdict[verdict.verdict + " (" + verdict.reason + ")"].push_back(
        input.Label(static_cast<int>(i)));
  }
  const size_t held =
      summary.frame_verdicts.size() -
      std::accumulate(by_verdict.begin(), by_verdict.end(), size_t{0},
                      [](size_t sum, const auto& entry) { return sum + entry.second.size(); });
  spdlog::info(fmt::format("refine: frames: {} held by their matches", held));
  for (const auto& [what, names] : by_verdict) {
    const bool doubted = what.rfind(kVerdictDoubted, 0) == 0;
    spdlog::log(doubted ? spdlog::level::warn : spdlog::level::info,
                fmt::format("refine: frames {}: {}", what, fmt::join(names, ", ")));
  }
}

}  // namespace

RefineSummary RefinePoses(const RefineInput& input, const RefineOptions& options,
                          RefineOutput* output) {
  const auto start = std::chrono::steady_clock::now();
  ValidateOptions(options, "refine");
  ValidateInput(input);
  const int n = static_cast<int>(input.prior_world_from_cam.size());
  // 1. The match graph's components; images no pair with matches touches are not solved.
  const MatchComponents split = SplitMatchComponents(input);
  if (split.components.empty()) {
    throw InputError("refine: no image pair with matches joins two of the " + std::to_string(n) +
                     " images: nothing to refine");
  }
  *output = UnsolvedOutput(input);
  FrameEvidence evidence;
  evidence.prior = output->world_from_cam;
  evidence.component.assign(n, -1);
  evidence.stated = input.stated_prior;
  evidence.prior_from_matches = input.prior_rotations_from_matches;
  for (int i = 0; i < n; ++i) evidence.labels.push_back(input.Label(i));
  NotRefined(split.unmatched, "unmatched",
             "no verified pair joins it to another image: not refined", &evidence);
  // 2. Each component solved (a self-calibrated camera comes from one solve: the largest only).
  RefineSummary summary;
  Warnings warnings;
  for (size_t c = 0; c < split.components.size(); ++c) {
    const std::vector<int>& images = split.components[c];
    for (const int image : images) evidence.component[image] = static_cast<int>(c);
    ComponentSummary record;
    record.num_images = static_cast<int>(images.size());
    record.first_image = input.Label(images.front());
    if (c > 0 && options.SelfCalibrates()) {
      NotRefined(images, "not_solved",
                 "its component is not the largest, and a self-calibrating run refines one solve: "
                 "not refined",
                 &evidence);
      summary.components.push_back(record);
      continue;
    }
    if (split.components.size() > 1) {
      spdlog::info(fmt::format("refine: component {} of {}: {} images from {}", c + 1,
                               split.components.size(), images.size(), record.first_image));
    }
    RefineSummary part =
        SolveComponent(input, options, images, c == 0, output, &evidence, &warnings);
    AddSolveWarnings(input, part, images, &warnings);
    record.solved = true;
    record.total_iterations = part.total_iterations;
    record.final_cost = part.final_cost;
    record.guardrails_fired = part.guardrails.fired;
    record.returned_prior = part.guardrails.returned_prior;
    if (c == 0) {
      summary = std::move(part);
      const OrientationPriorProbe& probe = summary.orientation_prior;
      evidence.probe_run = probe.enabled && !probe.prior_from_matches && probe.weight > 0;
      evidence.probe_kept = evidence.probe_run && probe.kept;
    } else {
      AddComponent(part, images, &summary);
    }
    summary.components.push_back(record);
  }
  // 3. One verdict per frame from all of it; the warnings that name the frames not held.
  evidence.solution = output->world_from_cam;
  summary.frame_verdicts = JudgeFrames(evidence, &summary.prior_trust);
  AddFrameWarnings(input, summary.frame_verdicts, summary.components, split.components, &warnings);
  summary.warnings = std::move(warnings);
  summary.timings.total_seconds = SecondsSince(start);
  LogFrameVerdicts(input, summary);
  return summary;
}

nlohmann::json RefineSummary::ToJson() const { return *this; }

}  // namespace raytime
