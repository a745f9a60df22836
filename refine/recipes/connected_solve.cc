#include "refine/recipes/connected_solve.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "core/statistics.h"
#include "core/timing.h"
#include "refine/checks/frame_doubt.h"
#include "refine/checks/frame_intrinsics.h"
#include "refine/checks/guardrails.h"
#include "refine/recipes/basin_first.h"
#include "refine/recipes/refine_pass.h"
#include "refine/recipes/track_finish.h"
#include "refine/solve/camera_blocks.h"
#include "refine/solve/ray_time_init.h"

namespace raytime {
namespace {

std::vector<std::string> Labels(const RefineInput& input, const std::vector<int>& images) {
  std::vector<std::string> labels;
  for (const int image : images) labels.push_back(input.Label(image));
  return labels;
}

// Per image, its camera's intrinsics in `cameras` (indexed as input.cameras).
std::vector<CameraIntrinsics> ImageIntrinsics(const RefineInput& input,
                                              const std::vector<CameraIntrinsics>& cameras) {
  std::vector<CameraIntrinsics> out;
  for (const int camera : input.camera_index) out.push_back(cameras.at(camera));
  return out;
}

bool IsFinite(const Rigid3& pose) {
  return pose.rotation.coeffs().allFinite() && pose.translation.allFinite();
}

// The intrinsics blocks (refine/solve/camera_blocks.h): one shared set only when self-calibrating
// one, else the images' own cameras. Every pass of the run uses the same blocks.
void SetUpIntrinsicsBlocks(const RefineInput& input, const RefineOptions& options, PassState* state,
                           CameraBlocksSummary* cameras) {
  cameras->sharing = NameOf(options.intrinsics_sharing);
  std::vector<bool> camera_in_use(input.cameras.size(), false);
  for (const int camera : input.camera_index) camera_in_use[camera] = true;
  cameras->num_cameras =
      static_cast<int>(std::count(camera_in_use.begin(), camera_in_use.end(), true));
  if (options.intrinsics_sharing != IntrinsicsSharing::kShared) {
    state->cameras = PerCameraBlocks(input);
    return;
  }
  // Self-calibrating (RefineOptions relations).
  state->cameras = SharedBlock(input, &cameras->max_start_disagreement_px);
  cameras->cameras_differ = cameras->max_start_disagreement_px > kSharedCameraTolerancePx;
  if (cameras->cameras_differ) {
    spdlog::warn(fmt::format(
        "refine: {} cameras differ by up to {:.3g} px on the image from the shared intrinsics "
        "started at their median (intrinsics_sharing: shared); their per-image values are "
        "replaced by one refined set",
        cameras->num_cameras, cameras->max_start_disagreement_px));
  }
}

// The staged room recipe (§4.3): pass 1 poses only, light orientation anchor, capped matches,
// full GNC schedule; pass 2 the nominal pass as one warm solve at the nominal scale, its priors
// re-anchored at the pass-1 poses. Pass 1 decides where pass 2 starts, so it never starts from an
// earlier run's solution.
void RunStaged(const RefineInput& input, const RefineOptions& options, const PassSettings& nominal,
               const std::vector<Rigid3>& prior, PassState* state, RefineSummary* summary) {
  PassSettings pass1;
  pass1.name = "pass1_poses";
  pass1.max_matches_per_pair = options.stage1_max_matches_per_pair;
  pass1.orientation_weight = options.stage1_orientation_weight;
  pass1.scales = nominal.scales;
  pass1.intermediate = true;
  summary->passes.push_back(RunPass(input, options, pass1, prior, state));
  PassSettings pass2 = nominal;
  pass2.name = "pass2_self_calibration";
  pass2.scales = {nominal.scales.back()};
  const std::vector<Rigid3> pass1_poses = state->world_from_cam;
  summary->passes.push_back(RunPass(input, options, pass2, pass1_poses, state));
}

// The recipe's passes (RefineOptions::recipe). `pruned` receives the input less the pairs a
// basin-first solve removed.
void RunRecipe(const RefineInput& input, const RefineOptions& options,
               const std::vector<Rigid3>& prior, PassState* state, RefineSummary* summary,
               std::optional<RefineInput>* pruned) {
  const PassSettings nominal = NominalPass(options);
  switch (options.recipe) {
    case RefineRecipe::kSingle:
      summary->passes.push_back(RunPass(input, options, nominal, prior, state));
      return;
    case RefineRecipe::kStaged:
      RunStaged(input, options, nominal, prior, state, summary);
      return;
    case RefineRecipe::kBasinFirst:
      RunBasinFirst(input, options, nominal, prior, state, summary, pruned);
      return;
  }
}

// Iterations, times, costs and failure over the passes.
void AddUpPasses(RefineSummary* summary) {
  for (const RefinePassSummary& pass : summary->passes) {
    summary->timings.build_seconds += pass.build_seconds;
    summary->timings.solve_seconds += pass.solve_seconds;
    for (const GncStageSummary& stage : pass.stages) {
      summary->total_iterations += stage.iterations;
      summary->timings.jacobian_seconds += stage.jacobian_seconds;
      summary->guardrails.solver_failed =
          summary->guardrails.solver_failed || stage.termination == GncTermination::kFailure;
    }
  }
  summary->initial_cost = summary->passes.front().stages.front().initial_cost;
  const RefinePassSummary& last = summary->passes.back();
  summary->final_cost = last.stages.back().final_cost -
                        (last.gauge_polish.prior_cost_before - last.gauge_polish.prior_cost_after);
}

// The posterior guardrails (§3.6, §4.3 and beyond the paper) and the decision they make.
void ApplyGuardrails(const RefineInput& input, const RefineOptions& options,
                     const std::vector<Rigid3>& prior, const PassState& state,
                     const std::vector<PairResidual>& pair_residuals, RefineSummary* summary) {
  // Against the original prior: these return it.
  if (summary->guardrails.solver_failed) summary->guardrails.fired.push_back("solver_failure");
  if (options.trust_region) {
    summary->guardrails.trust_region =
        CheckTrustRegion(prior, state.world_from_cam, options.trust_region_rotation_deg,
                         options.trust_region_translation_m * options.length_unit_m);
    if (summary->guardrails.trust_region.fired) summary->guardrails.fired.push_back("trust_region");
  }
  if (options.wander_test) {
    summary->guardrails.wander =
        CheckWander(prior, state.world_from_cam, options.wander_expected_m * options.length_unit_m,
                    options.wander_factor);
    if (summary->guardrails.wander.fired) summary->guardrails.fired.push_back("wander");
  }
  summary->guardrails.returned_prior = !summary->guardrails.fired.empty();
  // Against the solve's own matches (prior-independent), flag only.
  if (options.inconsistent_pairs_test) {
    summary->guardrails.inconsistent_pairs = CheckInconsistentPairs(
        pair_residuals, options.inconsistent_pair_px, options.inconsistent_pair_median_multiple,
        options.max_inconsistent_pair_fraction);
    if (summary->guardrails.inconsistent_pairs.fired) {
      summary->guardrails.fired.push_back("inconsistent_pairs");
    }
  }
  // A part resting on a pair or two nothing else checks looks consistent whether they are right or
  // not (its poses simply follow them), as does one whose disagreeing pairs the removal took.
  summary->guardrails.loose_parts = CheckLooseParts(
      input, summary->pair_removal, state, options,
      options.inconsistent_pairs_test ? summary->guardrails.inconsistent_pairs.pair_threshold_px
                                      : options.inconsistent_pair_px);
  if (!summary->guardrails.loose_parts.images.empty())
    summary->guardrails.fired.push_back("loose_parts");

  if (summary->guardrails.returned_prior) {
    summary->decision = "returned_prior";
  } else if (!summary->guardrails.fired.empty()) {
    summary->decision = "flagged";
  } else if (!summary->pair_removal.removed.empty()) {
    summary->decision = "re_solved";
  } else {
    summary->decision = "accepted";
  }
}

void LogGuardrailMeasures(const RefineSummary& summary) {
  if (summary.guardrails.trust_region.enabled) {
    spdlog::info(
        fmt::format("refine: trust region: moved at most {:.3f}° / {:.4g} (thresholds {:.3g}° / "
                    "{:.4g}){}",
                    summary.guardrails.trust_region.max_rotation_deg,
                    summary.guardrails.trust_region.max_translation,
                    summary.guardrails.trust_region.rotation_threshold_deg,
                    summary.guardrails.trust_region.translation_threshold,
                    summary.guardrails.trust_region.fired ? ": FIRED" : ""));
  }
  if (summary.guardrails.wander.enabled) {
    spdlog::info(fmt::format(
        "refine: wander test: median Sim(3)-aligned displacement {:.4g} (threshold "
        "{:.4g}){}",
        summary.guardrails.wander.median_displacement, summary.guardrails.wander.threshold,
        summary.guardrails.wander.fired ? ": FIRED" : ""));
  }
  const InconsistentPairsVerdict& pairs = summary.guardrails.inconsistent_pairs;
  if (pairs.enabled) {
    spdlog::info(fmt::format(
        "refine: inconsistent pairs: {} of {} pairs above {:.3g} px (median pair {:.3g} px), "
        "fraction {:.3f} (threshold {:.3g}){}",
        pairs.num_inconsistent, pairs.num_pairs, pairs.pair_threshold_px, pairs.median_pair_px,
        pairs.fraction, pairs.fraction_threshold, pairs.fired ? ": FIRED" : ""));
  }
  if (summary.guardrails.returned_prior) {
    spdlog::warn(fmt::format("refine: guardrail fired ({}): returning the prior",
                             summary.guardrails.fired.front()));
  }
  const PairRemovalSummary& removal = summary.pair_removal;
  if (removal.enabled) {
    spdlog::info(
        fmt::format("refine: pair removal: {} pair(s) removed in {} round(s), stopped: {}{}",
                    removal.removed.size(), removal.rounds, removal.stop_reason,
                    removal.kept.empty()
                        ? std::string()
                        : fmt::format(" ({} inconsistent pair(s) kept to hold the graph together)",
                                      removal.kept.size())));
  }
}

// The track finish (track_finish.h) on a solve the guardrails did not question; its solution is
// kept only when the guardrails judge it as they judged the ray-time one (the same decision, the
// same checks fired), else the ray-time solution stands and the summary says why. *pairs: the
// solved pairs' residuals, at the returned solution.
void RunTrackFinish(const RefineInput& input, const RefineInput& active,
                    const RefineOptions& options, const std::vector<Rigid3>& prior,
                    PassState* state, RefineSummary* summary, std::vector<PairResidual>* pairs) {
  TrackFinishSummary& finish = summary->track_finish;
  if (!options.track_finish) return;
  if (summary->decision != "accepted" && summary->decision != "re_solved") {
    finish.enabled = true;
    finish.reason =
        "the guardrails questioned the ray-time solution (decision " + summary->decision + ")";
    spdlog::info("refine: track finish not run: " + finish.reason);
    return;
  }
  const PassState ray_time_state = *state;
  const PoseUncertaintySummary ray_time_uncertainty = summary->uncertainty;
  finish = FinishOnTracks(active, options, summary->passes.back(), state, &summary->uncertainty);
  if (!finish.accepted) return;
  std::vector<PairResidual> adjusted_pairs = SolvedPairResiduals(active, *state);
  RefineSummary judged;
  judged.guardrails.solver_failed = summary->guardrails.solver_failed;
  judged.pair_removal = summary->pair_removal;
  ApplyGuardrails(input, options, prior, *state, adjusted_pairs, &judged);
  if (judged.decision == summary->decision &&
      judged.guardrails.fired == summary->guardrails.fired) {
    summary->guardrails = judged.guardrails;
    *pairs = std::move(adjusted_pairs);
    return;
  }
  finish.accepted = false;
  finish.reason = fmt::format(
      "the guardrails judge its solution otherwise (decision {}, fired [{}]; the ray-time "
      "solution's {}, [{}])",
      judged.decision, fmt::join(judged.guardrails.fired, ", "), summary->decision,
      fmt::join(summary->guardrails.fired, ", "));
  spdlog::warn("refine: track finish rejected, the ray-time solution stands: " + finish.reason);
  *state = ray_time_state;
  summary->uncertainty = ray_time_uncertainty;
}

// The loose parts (the outermost of nested ones: the others are in the summary), the decision and
// the inconsistent pairs, by image name.
void LogVerdicts(const RefineInput& input, const RefineSummary& summary) {
  const auto& cuts = summary.guardrails.loose_parts.cuts;
  for (const LooseCut& cut : cuts) {
    const auto holds = [&](const LooseCut& other) {
      return other.images.size() > cut.images.size() &&
             std::includes(other.images.begin(), other.images.end(), cut.images.begin(),
                           cut.images.end());
    };
    if (std::any_of(cuts.begin(), cuts.end(), holds)) continue;
    spdlog::warn(fmt::format(
        "refine: guardrail fired (loose_parts): {} image(s) held to the rest by {} pair(s) of "
        "{} matches{}; the matches do not hold their placement: {}",
        cut.images.size(), cut.pairs_across - cut.pairs_removed,
        cut.matches_across - cut.matches_removed,
        cut.pairs_removed == 0 ? std::string()
                               : fmt::format(" (the pair removal took {} of {} pairs across)",
                                             cut.pairs_removed, cut.pairs_across),
        fmt::join(Labels(input, cut.images), ", ")));
  }
  spdlog::info(fmt::format("refine: decision: {}", summary.decision));
  const InconsistentPairsVerdict& pairs = summary.guardrails.inconsistent_pairs;
  if (!pairs.fired) return;
  // The first few in the log; all of them in the summary.
  constexpr size_t kLogged = 8;
  std::string listed;
  for (size_t p = 0; p < std::min(kLogged, pairs.pairs.size()); ++p) {
    listed +=
        fmt::format("{}({}, {}) {:.1f} px", p == 0 ? "" : ", ", input.Label(pairs.pairs[p].image1),
                    input.Label(pairs.pairs[p].image2), pairs.pairs[p].median_px);
  }
  if (pairs.pairs.size() > kLogged) listed += ", ...";
  spdlog::warn(fmt::format(
      "refine: guardrail fired (inconsistent_pairs): the solution leaves {} of {} image pairs' "
      "matches unexplained (wrong pairs, e.g. repeated structure, may have pulled it off): {}{}",
      pairs.num_inconsistent, pairs.num_pairs, listed,
      pairs.images_mostly_inconsistent.empty()
          ? std::string()
          : fmt::format("; most pairs of image(s) {} are among them: their poses are likely wrong",
                        fmt::join(Labels(input, pairs.images_mostly_inconsistent), ", "))));
}

// The position prior in units of the prior's own depth scale D (issue 46): λp/N Σ |ΔO_i|² / D²,
// with D the median over the images of the "auto" ray-time start at the prior (the depth its
// matched rays meet at). The match term does not see the prior's unit; with λp per length² the
// prior's pull did: the demo's 4° prior in centimetres was refined to 5.6° (from 4.1°) and in
// millimetres to 9.5°, its centres held 10⁴-10⁶ times harder, and in kilometres to 0.03°. Per D²
// the solve is the same in any unit, and the paper's λp = 1e-2 is the weight at D = 1 m (its
// object and room captures). Without a depth sample (centres that coincide) λp stays as given.
constexpr int kDepthScaleMatchesPerPair = 100;

RefineOptions WithDepthScaledPositionPrior(const RefineInput& input, const RefineOptions& given,
                                           const std::vector<Rigid3>& prior, const PassState& state,
                                           RefineSummary* summary) {
  summary->prior_depth =
      PriorDepthScale(input, prior, state.cameras, kDepthScaleMatchesPerPair, given.match_cap_seed);
  RefineOptions options = given;
  if (std::isfinite(summary->prior_depth)) {
    options.position_weight /= summary->prior_depth * summary->prior_depth;
  }
  return options;
}

// refine/checks/frame_doubt.h's verdict on the returned solve.
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
  return CheckFrameDoubts(input.prior_world_from_cam, output.world_from_cam,
                          ImageIntrinsics(input, output.cameras), image, pixel, solved.ray_times,
                          solved.matches, options);
}

// Every frame, when the solve explains its matches nowhere (an arctan scale below the keypoints'
// noise, a prior far beyond the basin): such a solve is consistent with itself, since the
// inconsistent-pairs threshold rises with the median pair; its median pair above the absolute
// threshold says so. True when it does.
bool DoubtASolveThatExplainsNothing(const RefineOptions& options, const RefineOutput& output,
                                    std::vector<FrameFinding>* findings) {
  std::vector<double> pair_medians;
  for (const PairResidual& pair : output.diagnostics.pairs) pair_medians.push_back(pair.median_px);
  const double median_pair = Median(pair_medians, 0.0);
  if (!(median_pair > options.inconsistent_pair_px)) return false;
  for (int i = 0; i < static_cast<int>(output.world_from_cam.size()); ++i) {
    findings->push_back(
        {i, "unexplained_pairs",
         fmt::format("the solution explains its matches nowhere: the median pair's median "
                     "positive-ray epipolar distance is {:.3g} px, above {:.3g} px",
                     median_pair, options.inconsistent_pair_px)});
  }
  return true;
}

// Frames whose matches other intrinsics explain far better (frame_intrinsics.h), on every pair of
// `input`: a wrong focal length is what made the wrong-pair removal take a frame's pairs.
void TestIntrinsics(const RefineInput& input, const RefineOptions& options,
                    const RefineOutput& output, RefineSummary* summary,
                    std::vector<FrameFinding>* findings) {
  const auto start = std::chrono::steady_clock::now();
  const std::vector<FrameFinding> named = CheckFrameIntrinsics(
      input, output.world_from_cam, ImageIntrinsics(input, output.cameras),
      options.inconsistent_pair_px, options.Threads(), &summary->frame_intrinsics);
  findings->insert(findings->end(), named.begin(), named.end());
  const auto fitted =
      std::count_if(summary->frame_intrinsics.begin(), summary->frame_intrinsics.end(),
                    [](const FrameIntrinsicsTest& t) { return t.fitted; });
  spdlog::info(fmt::format(
      "refine: intrinsics test: {} of {} frames fit worse than the others and were refitted, {} "
      "explained far better by other intrinsics ({:.2f} s)",
      fitted, summary->frame_intrinsics.size(), named.size(), SecondsSince(start)));
}

// The frames most of whose pairs the solution leaves unexplained (guardrails.h).
void NameUnexplainedFrames(const RefineSummary& summary, const RefineOutput& output,
                           std::vector<FrameFinding>* findings) {
  const InconsistentPairsVerdict& pairs = summary.guardrails.inconsistent_pairs;
  for (const int image : pairs.images_mostly_inconsistent) {
    int unexplained = 0, total = 0;
    for (const PairResidual& pair : output.diagnostics.pairs) {
      if (pair.image1 != image && pair.image2 != image) continue;
      ++total;
      unexplained += !(pair.median_px <= pairs.pair_threshold_px);
    }
    findings->push_back(
        {image, "unexplained_pairs",
         fmt::format("the solution leaves {} of its {} pairs unexplained (median positive-ray "
                     "epipolar distance above {:.3g} px): its pose is likely wrong",
                     unexplained, total, pairs.pair_threshold_px)});
  }
}

// The frames that moved far more than the others and fit worse, or fit far worse alone
// (frame_doubt.h).
void DoubtFramesThatStandOut(const RefineInput& active, const RefineOptions& options,
                             const RefineOutput& output, RefineSummary* summary,
                             std::vector<FrameFinding>* findings) {
  summary->frame_doubts = FrameDoubtsOf(active, output, options.frame_doubt);
  const FrameDoubtVerdict& doubts = summary->frame_doubts;
  for (const int image : doubts.images) {
    if (doubts.centre_change[image] <= doubts.centre_change_threshold) {
      findings->push_back(
          {image, "fits_far_worse",
           fmt::format("its matches fit {:.1f}x worse than the median pair's (doubted above "
                       "{:g}x alone): a frame its matches do not place (another scene's image, "
                       "wrong intrinsics)",
                       doubts.residual_ratio[image], options.frame_doubt.far_residual_ratio)});
      continue;
    }
    findings->push_back(
        {image, "moved_and_fits_worse",
         fmt::format("the solve moved it {:.3g} (the median frame {:.3g}, prior length units) and "
                     "its matches fit {:.2f}x worse than the median pair's: wrong intrinsics, or "
                     "a frame the solve could not place",
                     doubts.centre_change[image], doubts.median_centre_change,
                     doubts.residual_ratio[image])});
  }
}

// The frames the returned solve (not a returned prior) leaves in doubt, most decisive first: a
// non-finite pose; every frame of a solve that explains nothing; frames other intrinsics explain
// far better, most of whose pairs are unexplained, that stand out. `active` is the input the last
// passes solved (without the pairs the removal took).
void CheckFrames(const RefineInput& input, const RefineInput& active, const RefineOptions& options,
                 const RefineOutput& output, RefineSummary* summary,
                 std::vector<FrameFinding>* findings) {
  for (int i = 0; i < static_cast<int>(output.world_from_cam.size()); ++i) {
    if (!IsFinite(output.world_from_cam[i])) {
      findings->push_back({i, "non_finite", "the solve returned a non-finite pose"});
    }
  }
  if (summary->guardrails.returned_prior) return;
  if (DoubtASolveThatExplainsNothing(options, output, findings)) return;
  if (options.check_frame_intrinsics) TestIntrinsics(input, options, output, summary, findings);
  NameUnexplainedFrames(*summary, output, findings);
  // A prior made from the match graph (the bootstrap's, or one its repair replaced) is no
  // independent measurement to stand out from: its own errors (a translation-averaging drift
  // at a sequence's ends) doubted correct end frames of entry-P10 at 32°.
  if (options.check_frame_doubts && !active.prior_rotations_from_matches) {
    DoubtFramesThatStandOut(active, options, output, summary, findings);
  }
}

}  // namespace

RefineSummary SolveConnected(const RefineInput& input, const RefineOptions& given,
                             RefineOutput* output, std::vector<FrameFinding>* findings) {
  const auto start = std::chrono::steady_clock::now();
  RefineSummary summary;

  std::vector<Rigid3> prior = input.prior_world_from_cam;
  for (Rigid3& pose : prior) pose.rotation.normalize();
  PassState state;
  state.world_from_cam = prior;
  SetUpIntrinsicsBlocks(input, given, &state, &summary.cameras);
  const RefineOptions options = WithDepthScaledPositionPrior(input, given, prior, state, &summary);
  std::optional<RefineInput> pruned;
  RunRecipe(input, options, prior, &state, &summary, &pruned);
  AddUpPasses(&summary);
  CountBlocks(state, &summary.cameras);
  spdlog::info(fmt::format(
      "refine: {} camera(s), {} intrinsics block(s) ({}{}), fewest observations on one: {}",
      summary.cameras.num_cameras, summary.cameras.num_blocks,
      options.SelfCalibrates() ? "self-calibrated, " : "fixed",
      options.SelfCalibrates() ? NameOf(options.intrinsics_sharing) : "",
      summary.cameras.min_block_observations));
  summary.uncertainty = PoseUncertaintyOf(input, options, state, summary.passes.back(), prior);
  if (summary.uncertainty.computed) {
    spdlog::info(fmt::format(
        "refine: uncertainty at the solution (keypoint noise {:.3g} px): median σ {:.3g}° "
        "rotation, {:.3g} centre ({:.2f} s)",
        summary.uncertainty.sigma_px, summary.uncertainty.median_rotation_deg,
        summary.uncertainty.median_centre, summary.uncertainty.seconds));
  }
  output->diagnostics.pairs = SolvedPairResiduals(pruned ? *pruned : input, state);
  output->diagnostics.image_residual_median_px = state.image_residual_median_px;
  ApplyGuardrails(input, options, prior, state, output->diagnostics.pairs, &summary);
  RunTrackFinish(input, pruned ? *pruned : input, options, prior, &state, &summary,
                 &output->diagnostics.pairs);

  output->solved_world_from_cam = state.world_from_cam;
  output->solved_cameras = InputCameras(input, state.cameras);
  output->solved_observations = SolvedObservationsOf(state);
  for (const auto& [pass, poses] : state.pass_world_from_cam) {
    output->pass_world_from_cam[pass].assign(poses.begin(), poses.end());
  }
  output->world_from_cam = summary.guardrails.returned_prior ? prior : state.world_from_cam;
  output->cameras = summary.guardrails.returned_prior ? input.cameras : output->solved_cameras;
  CheckFrames(input, pruned ? *pruned : input, options, *output, &summary, findings);
  summary.timings.total_seconds = SecondsSince(start);
  LogGuardrailMeasures(summary);
  LogVerdicts(input, summary);
  return summary;
}

}  // namespace raytime
