// The refiner's public types (issue 31: the internal headers include these, never the entry
// header refine.h): its input (cameras, prior poses, keypoints, matches), its output (poses, the
// solve's observations) and the summaries a solve returns (passes, GNC stages, the checks'
// verdicts), which evaluation, the stage's summary.json and the logs read.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "core/named_enum.h"
#include "core/warnings.h"
#include "refine/checks/frame_doubt.h"
#include "refine/checks/frame_verdicts.h"
#include "refine/checks/loose_parts.h"
#include "refine/checks/pose_uncertainty.h"
#include "refine/solve/gauge_polish.h"

namespace raytime {

// Matches of one image pair: rows of (keypoint index in image1, keypoint index in image2).
struct PairMatchIndices {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
};

using Keypoints = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

// An earlier solution of an overlapping problem (the same capture before frames were added or
// removed, issue 34) to start the passes that solve on all matches from: they start near their
// minimum instead of at the capped passes' solution, and converge in fewer iterations. Only the
// start changes: the capped passes, whose solutions make the recipe's decisions (wrong-pair
// removal, the orientation-prior probe), and every prior term are as without it.
struct RefineWarmStart {
  // Per pass name ("solve", "finish", "finish_anneal"), per image of the input: its pose at the
  // end of that pass in the earlier solve; none for an image it did not have.
  std::map<std::string, std::vector<std::optional<Rigid3>>> world_from_cam;
  // Ray times of the earlier solve's last pass, keyed by WarmRayTimeKey(image, keypoint) (image
  // and keypoint of this input; only where the keypoint is the same one).
  std::unordered_map<uint64_t, double> ray_times;
};
// (image, keypoint) as one key, as the passes key their solved ray times (PassState).
inline uint64_t WarmRayTimeKey(int image, int keypoint) {
  return (static_cast<uint64_t>(image) << 32) | static_cast<uint32_t>(keypoint);
}

struct RefineInput {
  // The cameras' intrinsics (SPEC §2) and, per image, the index of its camera: one camera when
  // the images share intrinsics (the paper's setting, §3.1), several for per-frame intrinsics
  // (phone captures). refine/solve/camera_blocks.h says how they become the solve's parameter
  // blocks.
  std::vector<CameraIntrinsics> cameras;
  std::vector<int> camera_index;             // one per image, into cameras
  std::vector<Rigid3> prior_world_from_cam;  // one per image
  std::vector<Keypoints> keypoints;          // per image: distorted pixels, OpenCV convention
  std::vector<PairMatchIndices> pairs;       // indices into the images above
  // The prior's rotations were estimated from these same matches (the bootstrap: rotation
  // averaging of five-point relative poses, §4.8 "Refinement without an external prior"). An
  // orientation prior towards them brings no information the matches lack, only their averaging
  // errors, so the basin-first solve finishes without one and does not probe it.
  bool prior_rotations_from_matches = false;
  // Per image, its name for the log's verdicts (a user reads frames by name, not by index); empty:
  // the log says indices.
  std::vector<std::string> names;
  RefineWarmStart warm_start;  // empty: every pass starts as the recipe says
  // The prior's accuracy per frame as the user states it (prior.sigma_deg / prior.sigma_m): a
  // prior trusted to place the frames its matches do not hold (refine/checks/frame_verdicts.h).
  StatedPriorAccuracy stated_prior;

  const CameraIntrinsics& CameraOf(int image) const { return cameras[camera_index[image]]; }
  // names[image], or its index when there are no names.
  std::string Label(int image) const {
    return image >= 0 && static_cast<size_t>(image) < names.size() ? names[image]
                                                                   : std::to_string(image);
  }
};

// The last pass's observations and where the solve put them (paper §3.2, X = O + t·D): what an
// export turns into initial 3D points without triangulating (splat/trainer_export.h).
struct SolvedObservations {
  // Rows: image (index into RefineInput's images), keypoint (row of its keypoints); sorted.
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> observations;
  // Per observation: its ray time at the solve, along the unit ray from the camera centre (length
  // units of the prior); NaN for an observation that owns none (anchored: the non-anchors).
  Eigen::VectorXd ray_times;
  // The used matches (after the cap), as rows of `observations`.
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
};

// One image pair's fit at the solve (refine/checks/pair_consistency.h): the median over its used
// matches of the symmetric epipolar distance restricted to positive ray times (the cross-projection
// residual minimized over the ray time) at the solved poses and intrinsics.
struct PairResidual {
  int image1 = 0;  // indices into RefineInput's images
  int image2 = 0;
  int num_matches = 0;     // used matches (after the cap)
  double median_px = 0.0;  // pixels, root mean square of the two directions per match
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PairResidual, image1, image2, num_matches, median_px)

// How the returned solve fits the matches, per image and per image pair (the run page's camera
// table and pair-consistency matrix): too large for the summary, written beside the poses.
struct SolveDiagnostics {
  // Every pair with used matches in the last pass, at the solve (input order; the pairs the
  // pair removal took are in RefineSummary::pair_removal, not here).
  std::vector<PairResidual> pairs;
  // Per image: the median norm of the cross-projection residuals landing in it (paper eqs. rij,
  // rji: π_image(X) − û), pixels, NaN for an image no residual reaches.
  std::vector<double> image_residual_median_px;
};

struct RefineOutput {
  std::vector<Rigid3> world_from_cam;  // the solution, or the prior when a guardrail fired
  // Per camera of the input: refined when self-calibrating (with intrinsics_sharing 'shared',
  // every camera an image uses holds the one shared set), else the input's; the input's also
  // when a guardrail fired.
  std::vector<CameraIntrinsics> cameras;
  // The solve's own result even when the prior was returned (for diagnostics).
  std::vector<Rigid3> solved_world_from_cam;
  std::vector<CameraIntrinsics> solved_cameras;
  // At solved_world_from_cam and solved_cameras (so not the returned poses when a guardrail fired).
  SolvedObservations solved_observations;
  SolveDiagnostics diagnostics;  // at the solve, as solved_observations
  // Per pass name, the poses at its end (none for an image no solve of that pass had): a later
  // run's RefineWarmStart.
  std::map<std::string, std::vector<std::optional<Rigid3>>> pass_world_from_cam;
};

// The bins of a GNC stage's residual histogram (GncStageSummary::residual_histogram): norms of the
// cross-projection residuals in pixels, in 1-2-5 steps; bin 0 holds the norms below the first
// edge, bin k those in [edge k-1, edge k), the last those from the last edge up.
inline const std::vector<double>& ResidualHistogramEdgesPx() {
  static const std::vector<double> edges = {0.05, 0.1, 0.2, 0.5, 1,   2,   5,
                                            10,   20,  50,  100, 200, 500, 1000};
  return edges;
}

// Counts of `norms_px` in the bins of ResidualHistogramEdgesPx() (edges + 1 bins).
std::vector<int> ResidualHistogram(const std::vector<double>& norms_px);

// One solve of the GNC schedule (§3.5).
// Why a GNC stage stopped: Ceres' TerminationType, which the ray-time LM reports too; written as
// Ceres writes it (TerminationTypeToString). FAILURE ends the schedule and returns the prior.
enum class GncTermination { kConvergence, kNoConvergence, kFailure, kUserSuccess, kUserFailure };
constexpr std::array<EnumName<GncTermination>, 5> EnumNames(GncTermination) {
  return {{{GncTermination::kConvergence, "CONVERGENCE"},
           {GncTermination::kNoConvergence, "NO_CONVERGENCE"},
           {GncTermination::kFailure, "FAILURE"},
           {GncTermination::kUserSuccess, "USER_SUCCESS"},
           {GncTermination::kUserFailure, "USER_FAILURE"}}};
}

struct GncStageSummary {
  double loss_scale_px2 = 0.0;
  int iterations = 0;  // successful + unsuccessful steps
  int successful_steps = 0;
  double initial_cost = 0.0;  // Ceres cost = E of paper eq. (energy) at this stage's scale
  double final_cost = 0.0;
  double seconds = 0.0;
  double jacobian_seconds = 0.0;  // Ceres: Jacobian evaluation (includes the cache)
  double residual_seconds = 0.0;  // Ceres: residual-only evaluation
  double linear_solver_seconds = 0.0;
  int jacobian_evaluations = 0;
  int step_doublings = 0;  // ray-time LM: accepted doublings of an accepted step
  // The relative cost-change tolerance the stage stopped on (GncSettings::StageTolerance).
  double function_tolerance = 0.0;
  GncTermination termination = GncTermination::kNoConvergence;
  std::string message;
  // The residual norms at the stage's solution binned by ResidualHistogramEdgesPx() (how the
  // annealing pulls residuals in: the run page draws one histogram per stage).
  std::vector<int> residual_histogram;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GncStageSummary, loss_scale_px2, iterations, successful_steps,
                                   initial_cost, final_cost, seconds, jacobian_seconds,
                                   residual_seconds, linear_solver_seconds, jacobian_evaluations,
                                   step_doublings, function_tolerance, termination, message,
                                   residual_histogram)

struct RayTimeInitSummary {
  std::string mode;              // "auto" or "constant"
  int num_depth_samples = 0;     // positive closest-approach depths found (auto)
  int images_with_fallback = 0;  // matched images without a sample (global median used)
  // Per-image initial depth over the matched images (length units of the prior).
  double min_depth = 0.0;
  double median_depth = 0.0;
  double max_depth = 0.0;
  // A later pass: ray times started at an earlier pass's solved value, and (basin-first finish)
  // the others started at their own closest approach at the current poses
  // (StartRayTimesAtClosestApproach, ray_time_init.h).
  int num_warm_started = 0;
  int num_closest_approach_started = 0;
  // From an earlier run's solution (RefineWarmStart): the images whose pose, and the ray times
  // (among num_warm_started) whose value, this pass started from.
  int num_images_from_earlier_run = 0;
  int num_ray_times_from_earlier_run = 0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RayTimeInitSummary, mode, num_depth_samples,
                                   images_with_fallback, min_depth, median_depth, max_depth,
                                   num_warm_started, num_closest_approach_started,
                                   num_images_from_earlier_run, num_ray_times_from_earlier_run)

// One pass of the refiner: a problem object and its GNC stages (two passes in the staged room
// recipe of §4.3, three in the basin-first solve, one otherwise).
struct RefinePassSummary {
  // "solve"; "pass1_poses" / "pass2_self_calibration" (staged); "basin" / "orientation_probe" /
  // "finish" (basin_first)
  std::string name;
  int num_cameras = 0;
  int num_observations = 0;   // distinct (image, keypoint) in the used matches
  int num_ray_times = 0;      // = observations (per_observation) or tracks (anchored)
  int num_tracks = 0;         // anchored only
  int num_matches_input = 0;  // matches between distinct images in the input
  int num_matches_used = 0;   // after the per-pair cap
  int num_residuals = 0;      // 2-vector cross-projection residuals
  // The eliminated group: the one Ceres' automatic ordering chose (should = ray times), or every
  // ray time (the ray-time LM solver eliminates them by construction).
  int elimination_group_size = 0;
  std::string solver;  // "ray_time_lm" or "ceres" (RefineOptions::solver)
  double orientation_weight = 0.0;
  bool self_calibration = false;
  RayTimeInitSummary ray_time_init;
  std::vector<GncStageSummary> stages;
  GaugePolishSummary gauge_polish;  // after the last stage (gauge_polish.h)
  // Norms of the cross-projection residuals (paper eqs. rij, rji, no loss) at the pass's solution,
  // pixels: the median and the 90th percentile (nearest rank) over the residuals.
  double residual_median_px = 0.0;
  double residual_p90_px = 0.0;
  // The match term at the solution: the mean over the residuals of the nominal arctan loss
  // rho(|r|^2) = a atan(|r|^2 / a), a = loss_scale_px2, px² (what the basin-first probe compares).
  double match_cost_px2 = 0.0;
  double build_seconds = 0.0;
  double solve_seconds = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RefinePassSummary, name, num_cameras, num_observations,
                                   num_ray_times, num_tracks, num_matches_input, num_matches_used,
                                   num_residuals, elimination_group_size, solver,
                                   orientation_weight, self_calibration, ray_time_init, stages,
                                   gauge_polish, residual_median_px, residual_p90_px,
                                   match_cost_px2, build_seconds, solve_seconds)

// Prior trust region (§3.6): per-frame motion of the solution from the prior, prior's frame.
struct TrustRegionVerdict {
  bool enabled = false;
  bool fired = false;
  double max_rotation_deg = 0.0;
  double max_translation = 0.0;  // prior length units
  double rotation_threshold_deg = 0.0;
  double translation_threshold = 0.0;  // trust_region_translation_m * length_unit_m
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TrustRegionVerdict, enabled, fired, max_rotation_deg,
                                   max_translation, rotation_threshold_deg, translation_threshold)

// Room-scale wander test (§4.3).
struct WanderVerdict {
  bool enabled = false;
  bool fired = false;
  double median_displacement = 0.0;  // after Sim(3) fit onto the prior, prior length units
  double expected = 0.0;             // wander_expected_m * length_unit_m
  double threshold = 0.0;            // wander_factor * expected
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(WanderVerdict, enabled, fired, median_displacement, expected,
                                   threshold)

// Inconsistent-pairs test (beyond the paper; cf. its §4.11 "Failure analysis"): the fraction of
// image pairs whose matches the solution does not explain. Flag only: the solution is returned.
struct InconsistentPairsVerdict {
  bool enabled = false;
  bool fired = false;
  int num_pairs = 0;  // image pairs with used matches
  int num_inconsistent = 0;
  double fraction = 0.0;        // num_inconsistent / num_pairs
  double median_pair_px = 0.0;  // median (upper) over the pairs of their medians, pixels
  // max(inconsistent_pair_px, median_multiple x median_pair_px) (inconsistent_pair_median_multiple)
  double pair_threshold_px = 0.0;
  double median_multiple = 0.0;
  double fraction_threshold = 0.0;  // max_inconsistent_pair_fraction
  std::vector<PairResidual> pairs;  // the inconsistent pairs, in input order
  // Images in at least kMinInconsistentPairsOfAnImage (guardrails.h) inconsistent pairs that are
  // more than half of their pairs, or all of whose pairs (one at least) are inconsistent,
  // ascending: a wrong pair involves two images, so when most of one image's pairs are
  // unexplained, its pose (a frame the solve did not place) is the likelier culprit. Named
  // whether or not the test fired.
  std::vector<int> images_mostly_inconsistent;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(InconsistentPairsVerdict, enabled, fired, num_pairs,
                                   num_inconsistent, fraction, median_pair_px, pair_threshold_px,
                                   median_multiple, fraction_threshold, pairs,
                                   images_mostly_inconsistent)

// The basin-first solve's orientation-prior probe (`recipe: basin_first`): whether the
// matches agree with the prior's rotations, and so whether the finish keeps λR.
struct OrientationPriorProbe {
  bool enabled = false;
  double weight = 0.0;  // λR probed (orientation_weight), 1/rad²
  // The median cross-projection residual (RefinePassSummary::residual_median_px) of the basin
  // solve (λR = 0) and of the probe (λR = weight) on the same matches, pixels, and the mean match
  // terms (match_cost_px2) beside them.
  double free_residual_median_px = 0.0;
  double prior_residual_median_px = 0.0;
  double free_match_cost_px2 = 0.0;
  double prior_match_cost_px2 = 0.0;
  double increase = 0.0;                 // prior_residual_median_px / free_... - 1
  double max_increase = 0.0;             // orientation_prior_max_increase
  double max_rotation_change_deg = 0.0;  // largest per-frame rotation between the two solutions
  bool kept = false;                     // the finish runs with λR = weight (else 0)
  // Not probed: the prior's rotations came from the matches (RefineInput), the finish runs with
  // λR = 0.
  bool prior_from_matches = false;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(OrientationPriorProbe, enabled, weight, free_residual_median_px,
                                   prior_residual_median_px, free_match_cost_px2,
                                   prior_match_cost_px2, increase, max_increase,
                                   max_rotation_change_deg, kept, prior_from_matches)

// The track finish (RefineOptions::track_finish, refine/recipes/track_finish.h): a bundle
// adjustment with one point per track from the ray-time solution, returned only when its own check
// passes.
struct TrackFinishSummary {
  bool enabled = false;
  bool ran = false;
  bool accepted = false;  // its poses were returned (else the ray-time solution's)
  // Why it did not run, or was rejected; "accepted" when it was returned.
  std::string reason;
  int num_matches = 0;       // the last pass's used matches
  int num_inliers = 0;       // those both of whose residuals were within inlier_threshold_px
  int num_tracks = 0;        // their union-find components, one observation per image
  int num_conflicting = 0;   // components left out: two keypoints of one image
  int num_observations = 0;  // of the adjusted tracks
  int num_rejected = 0;      // observations the rejection round took
  double inlier_threshold_px = 0.0;
  double loss_scale_px2 = 0.0;
  int iterations = 0;
  // The keypoint noise each estimator's residuals imply (PoseUncertaintySummary::sigma_px), px.
  double ray_time_sigma_px = 0.0;
  double points_sigma_px = 0.0;  // the tracks' points at the ray-time poses, before adjusting
  double adjusted_sigma_px = 0.0;
  // The largest per-frame move from the ray-time solution, in degrees and prior length units and
  // as multiples of that frame's ray-time σ, and the frame it was.
  double max_rotation_move_deg = 0.0;
  double max_centre_move = 0.0;
  double max_move_sigma = 0.0;
  int max_move_image = -1;
  double median_move_sigma = 0.0;  // the median frame's move, in its ray-time σ
  double seconds = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TrackFinishSummary, enabled, ran, accepted, reason, num_matches,
                                   num_inliers, num_tracks, num_conflicting, num_observations,
                                   num_rejected, inlier_threshold_px, loss_scale_px2, iterations,
                                   ray_time_sigma_px, points_sigma_px, adjusted_sigma_px,
                                   max_rotation_move_deg, max_centre_move, max_move_sigma,
                                   max_move_image, median_move_sigma, seconds)

// The basin-first solve's wrong-pair removal (RefineOptions::max_pair_removal_rounds).
struct PairRemovalSummary {
  bool enabled = false;
  int rounds = 0;  // basin solves rerun from the prior without removed pairs
  // The pairs the returned solve was made without, worst first, each with its measure at the basin
  // solution that removed it (indices into RefineInput's images).
  std::vector<PairResidual> removed;
  // Inconsistent pairs left in because removing them would split the match graph, with their
  // measure when they were kept.
  std::vector<PairResidual> kept;
  // "consistent": no pair above the threshold at the last basin solution; "stable": exactly the
  // removed pairs are; "cycle": an earlier round removed the set now above it, and that round's
  // solution is returned; "max_rounds": the bound was reached with another set above it.
  std::string stop_reason;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PairRemovalSummary, enabled, rounds, removed, kept, stop_reason)

// Parts of the match graph the matches do not hold (refine/checks/loose_parts.h): held by one pair,
// by two with few matches, or by fewer pairs than the wrong-pair removal took across. The check
// "loose_parts" fires when there is one (flag only; the refine stage names the images and the
// export leaves them out).
struct LoosePartsVerdict {
  std::vector<LooseCut> cuts;
  std::vector<int> images;  // the cuts' sides together, ascending
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(LoosePartsVerdict, cuts, images)

// How the images' cameras became the solve's intrinsics blocks (refine/solve/camera_blocks.h).
struct CameraBlocksSummary {
  std::string sharing;  // RefineOptions::intrinsics_sharing
  int num_cameras = 0;  // distinct cameras among the images (RefineInput::cameras in use)
  // Intrinsics blocks the last pass's residuals reach (held constant unless self-calibrating),
  // and the fewest observations (undistorted in its camera) one of them has.
  int num_blocks = 0;
  int min_block_observations = 0;
  // 'shared' only: the largest CameraDisagreementPx between an image's given camera and the
  // shared start, and whether it exceeds kSharedCameraTolerancePx (the given per-image
  // intrinsics were replaced by one set: the stage's warning cameras_shared).
  double max_start_disagreement_px = 0.0;
  bool cameras_differ = false;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(CameraBlocksSummary, sharing, num_cameras, num_blocks,
                                   min_block_observations, max_start_disagreement_px,
                                   cameras_differ)

// Wall time of a refine call, seconds: totals over passes and stages.
struct RefineTimings {
  double build_seconds = 0.0;
  double solve_seconds = 0.0;
  double jacobian_seconds = 0.0;
  double total_seconds = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RefineTimings, build_seconds, solve_seconds, jacobian_seconds,
                                   total_seconds)

// The posterior guardrails' verdicts (§3.6, §4.3 and beyond the paper).
struct RefineGuardrails {
  // "solver_failure", "trust_region", "wander" (these return the prior), "inconsistent_pairs",
  // "loose_parts" (flag only), in this order.
  std::vector<std::string> fired;
  bool returned_prior = false;
  bool solver_failed = false;  // a Ceres solve reported FAILURE
  TrustRegionVerdict trust_region;
  WanderVerdict wander;
  InconsistentPairsVerdict inconsistent_pairs;
  LoosePartsVerdict loose_parts;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RefineGuardrails, fired, returned_prior, solver_failed,
                                   trust_region, wander, inconsistent_pairs, loose_parts)

// One connected component of the match graph and its solve (refine/recipes/components.h).
struct ComponentSummary {
  int num_images = 0;
  std::string first_image;  // its first image's label
  bool solved = false;      // false: self-calibration refines one component, the largest
  int total_iterations = 0;
  double final_cost = 0.0;
  std::vector<std::string> guardrails_fired;
  bool returned_prior = false;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ComponentSummary, num_images, first_image, solved,
                                   total_iterations, final_cost, guardrails_fired, returned_prior)

// The passes, checks and verdicts of a run: the largest component's solve, and over all
// components the guardrails fired, the components, the frame verdicts and the warnings.
struct RefineSummary {
  std::vector<RefinePassSummary> passes;
  CameraBlocksSummary cameras;
  // Totals over passes and stages.
  int total_iterations = 0;
  double initial_cost = 0.0;  // first stage of the first pass
  // E at the returned solve: the last stage's final cost (the nominal objective) less what the
  // last pass's gauge polish removed from the prior terms.
  double final_cost = 0.0;
  RefineTimings timings;
  OrientationPriorProbe orientation_prior;
  PairRemovalSummary pair_removal;
  // What was returned, one word: "accepted" (no check fired), "re_solved" (accepted after
  // removing pairs, pair_removal), "flagged" (returned with a flag-only check fired),
  // "returned_prior" (a check returned the prior).
  std::string decision;
  RefineGuardrails guardrails;
  // How well the last pass's solution determines each camera (refine/checks/pose_uncertainty.h).
  PoseUncertaintySummary uncertainty;
  TrackFinishSummary track_finish;
  // The bins of every GNC stage's residual_histogram (ResidualHistogramEdgesPx()).
  std::vector<double> residual_histogram_edges_px = ResidualHistogramEdgesPx();
  // D, the prior's depth scale the position prior is measured in (λp/N Σ|ΔO|²/D²; prior length
  // units; null when the prior gave no depth sample and λp was used as given).
  double prior_depth = std::numeric_limits<double>::quiet_NaN();
  // The match graph's components (largest first), each with its solve's totals.
  std::vector<ComponentSummary> components;
  // The frame-doubt check of the largest component (refine/checks/frame_doubt.h), and every solved
  // frame's intrinsics test (refine/checks/frame_intrinsics.h).
  FrameDoubtVerdict frame_doubts;
  std::vector<FrameIntrinsicsTest> frame_intrinsics;
  // Per image: held, held_by_prior or doubted, and why (refine/checks/frame_verdicts.h); how the
  // prior was judged.
  std::vector<FrameVerdict> frame_verdicts;
  PriorTrust prior_trust;
  // What deserves a second look, by image name (core/warnings.h): doubted and held_by_prior
  // frames, guardrails that fired, a graph in pieces.
  Warnings warnings;

  nlohmann::json ToJson() const;  // the fields by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RefineSummary, passes, cameras, total_iterations, initial_cost,
                                   final_cost, timings, orientation_prior, pair_removal, decision,
                                   guardrails, uncertainty, track_finish,
                                   residual_histogram_edges_px, prior_depth, components,
                                   frame_doubts, frame_intrinsics, frame_verdicts, prior_trust,
                                   warnings)

}  // namespace raytime
