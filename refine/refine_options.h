// Options of the ray-time refiner (SPEC §3, paper §3.2–3.7, §4.3). Defaults are the paper's
// headline configuration; every field is listed once in VisitFields (YAML key = field name).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "core/named_enum.h"
#include "core/options.h"
#include "refine/checks/frame_doubt.h"

namespace raytime {

// The choices among fixed sets of ways, each with its option's names (the YAML values, and the
// text in provenance and summaries); RefineOptions says what each one does.
enum class RefineRecipe { kSingle, kStaged, kBasinFirst };
constexpr std::array<EnumName<RefineRecipe>, 3> EnumNames(RefineRecipe) {
  return {{{RefineRecipe::kSingle, "single"},
           {RefineRecipe::kStaged, "staged"},
           {RefineRecipe::kBasinFirst, "basin_first"}}};
}
enum class RefineSolver { kAuto, kCeres, kRayTimeLm };
constexpr std::array<EnumName<RefineSolver>, 3> EnumNames(RefineSolver) {
  return {{{RefineSolver::kAuto, "auto"},
           {RefineSolver::kCeres, "ceres"},
           {RefineSolver::kRayTimeLm, "ray_time_lm"}}};
}
enum class RayTimeParameterization { kPerObservation, kAnchored };
constexpr std::array<EnumName<RayTimeParameterization>, 2> EnumNames(RayTimeParameterization) {
  return {{{RayTimeParameterization::kPerObservation, "per_observation"},
           {RayTimeParameterization::kAnchored, "anchored"}}};
}
enum class RayTimeInitMode { kAuto, kConstant };
constexpr std::array<EnumName<RayTimeInitMode>, 2> EnumNames(RayTimeInitMode) {
  return {{{RayTimeInitMode::kAuto, "auto"}, {RayTimeInitMode::kConstant, "constant"}}};
}
enum class IntrinsicsSharing { kPerCamera, kShared };
constexpr std::array<EnumName<IntrinsicsSharing>, 2> EnumNames(IntrinsicsSharing) {
  return {{{IntrinsicsSharing::kPerCamera, "per_camera"}, {IntrinsicsSharing::kShared, "shared"}}};
}

struct RefineOptions {
  // Structure variables (§3.2, §3.6): "per_observation" = one ray time per matched observation
  // (the method); "anchored" = union-find tracks over the match graph, one ray time per track on
  // its anchor observation's ray (the ablation baseline).
  RayTimeParameterization parameterization = RayTimeParameterization::kPerObservation;

  // Arctan loss scale a of the nominal objective, px² (§3.3: rho(s) = a atan(s / a), a = 100).
  double loss_scale_px2 = 100.0;
  // GNC schedule (§3.5): arctan scales, px², solved in order on one problem object, each stage
  // warm-started from the previous one. loss_scale_px2 is appended when the list does not end
  // with it, so the last stage is exactly the nominal objective; [] or [loss_scale_px2] is a
  // plain solve.
  std::vector<double> gnc_scales = {1e4, 1e3, 1e2};

  // λp, weight of the position prior λp/N Σ |O_i - O_i^prior|² / D² (§3.3), D the prior's depth
  // scale (refine/recipes/connected_solve.cc): per length² in the paper, whose captures have D ~ 1
  // m; per D² the result does not depend on the prior's unit (issue 46).
  double position_weight = 1e-2;
  // λR, weight of the orientation prior λR/N Σ |Log(R_i^prior^-1 R_i)|², 1/rad² (§3.3, §3.6).
  double orientation_weight = 1e3;
  // Weight of the orientation prior when the gauge polish (refine/solve/gauge_polish.h) picks the
  // solution's global similarity after the solve, 1/rad². A global similarity changes neither the
  // shape nor the match term, so fitting it to the prior's rotations as well as its centres costs
  // no basin width even when the solve itself runs with λR = 0 (the basin preset): the frame
  // returned is the one that agrees best with the whole prior, and the absolute-frame rotation
  // error becomes that of the average prior rotation rather than of a fit to noisy centres.
  // 0 fits the gauge to the prior centres only. Beyond the paper (its basin arm keeps the
  // solve's own gauge; Table 8).
  double gauge_orientation_weight = 1e3;
  // Per-camera uncertainty at the solution (refine/checks/pose_uncertainty.h, issue 32): dense in
  // the cameras, O((6n)³), computed up to this many (its cost: docs/refine_options.md); 0 = off.
  int uncertainty_max_cameras = 300;

  // Ray-time initialization (§3.2, SPEC §3): "auto" = per image, the median of the positive
  // closest-approach depths of its matched rays under the prior poses (global median for an
  // image without one); a depth scale only, no structure is committed (no gates, no culling).
  // "constant" = every ray time at ray_time_constant_m (the paper's 1 m for metric object and
  // room captures).
  RayTimeInitMode ray_time_init = RayTimeInitMode::kAuto;
  double ray_time_constant_m = 1.0;  // prior length units (metres for a metric prior)

  // At most this many matches per image pair, drawn uniformly at random with a seed derived from
  // the pair's image indices and match_cap_seed (§4.7 "match capping": 100); 0 keeps all.
  int max_matches_per_pair = 0;
  int match_cap_seed = 0;

  // Self-calibration of the intrinsics (§3.1, §4.3); all off in headline object runs, where the
  // intrinsics blocks are constant and every image keeps its own camera's intrinsics as given.
  bool refine_focal = false;            // fx, fy (bounded positive)
  bool refine_principal_point = false;  // cx, cy
  bool refine_distortion = false;       // k1, k2, p1, p2
  // What self-calibration refines when the images come with several cameras (per-frame intrinsics
  // of phone captures; MobileBrick's focal drifts 0.9–2.9 % per scene, §4.6 "Ablation"):
  // "per_camera" = one set per camera of the input, each image on its own camera's set (a
  // single-camera capture has the paper's one shared set, §3.1); "shared" = one set for every
  // image, started at the per-parameter median over the images of their cameras' values, with the
  // warning cameras_shared when a given camera differs from that start by more than 1 px on the
  // image (refine/solve/camera_blocks.h). Per-camera sets need enough observations per camera to be
  // determined (a principal point is nearly a rotation of its own camera). With fixed intrinsics
  // the images' cameras are used as given, so "shared" needs a refine_* option.
  IntrinsicsSharing intrinsics_sharing = IntrinsicsSharing::kPerCamera;

  // Shared evaluation cache (§3.7): undistortion and ray points once per observation per
  // evaluation point, copied into each residual's Jacobian. With every intrinsic held (no
  // self-calibration) the undistorted rays do not change, so they are computed once per solve and
  // the residuals differentiate the rest in closed form (FixedIntrinsicsCrossProjectionCost). Off:
  // every residual recomputes its chain with automatic differentiation (same values and
  // Jacobians, slower).
  bool use_evaluation_cache = true;
  // The solver of each pass (§3.4, §3.7): "ray_time_lm" = the ray-time Levenberg–Marquardt solver
  // (refine/solve/ray_time_lm_solver.h: the ray times eliminated in closed form, no Ceres, any
  // thread count deterministic), which holds every intrinsic; "ceres" = Ceres' SPARSE_SCHUR for
  // every pass (the paper's mapping); "auto" = the ray-time LM for the passes that hold every
  // intrinsic, Ceres for those that self-calibrate. Both minimize the same objective with the same
  // step rule; their paths differ in the last digits. The only switch: no other option changes it
  // (a combination that cannot run is refused, CheckRelations).
  RefineSolver solver = RefineSolver::kAuto;
  // Threads for the cache and the ray-time LM solver (and for Ceres when not deterministic);
  // 0 = hardware concurrency.
  int num_threads = 0;
  // Bit-identical results for the same inputs whatever the thread count and scheduling
  // (DEVELOPERS.md; the ray-time LM solver always is): Ceres runs on one thread, since with more it
  // sums the cost, the gradient and the Schur complement's blocks in the order its threads finish;
  // the cache stays parallel (each observation's entry is computed on its own). false gives Ceres
  // num_threads too: faster on many cores, last digits differ between runs.
  bool deterministic = true;
  // Per GNC stage: Ceres iteration limit and relative cost-change tolerance (Ceres defaults are
  // 50 and 1e-6; warm-started stages converge well before the limit).
  int max_iterations = 100;
  double function_tolerance = 1e-6;
  // The same for a stage whose solution only starts another (beyond the paper, issue 34): the GNC
  // schedule's earlier scales, and every stage of a pass the recipe solves again from (the basin
  // and its removal rounds, the orientation probe, a finish the anneal follows, the staged recipe's
  // pass 1).
  // The last stage still stops at function_tolerance, so the solution is the tight one's (measured:
  // docs/refine_options.md).
  double intermediate_function_tolerance = 1e-4;
  // Ray-time LM (beyond the paper, issue 34): after an accepted step whose cost fell by more than
  // 1.5x the model's prediction, the step is doubled up to this many times while the cost keeps
  // falling (one cost evaluation each); 0 = plain Levenberg-Marquardt (measured:
  // docs/refine_options.md).
  int max_step_doublings = 3;

  // Prior trust region (§3.6 "Prior trust region"): when the solution moves any frame more than
  // these from the prior, measured per frame in the prior's own frame (no alignment: the
  // position prior anchors the gauge there), the prior is returned instead. Object-scale
  // thresholds (twice the MobileBrick training envelope, 1.75° / 10.8 mm).
  bool trust_region = true;
  double trust_region_rotation_deg = 3.5;     // degrees
  double trust_region_translation_m = 0.022;  // metres at object scale, times length_unit_m
  // Scale of the scene's length unit relative to the metric captures the translation thresholds
  // were derived on: trust_region_translation_m and wander_expected_m are multiplied by it
  // (1 for metric object and room captures; e.g. 30 for a building 30x deeper than an object
  // orbit, 1000 for a metric prior stored in millimetres).
  double length_unit_m = 1.0;

  // Room-scale wander test (§4.3): flags the solve when the median per-frame centre displacement
  // from the prior, after a Sim(3) fit of the solution's centres onto the prior's, exceeds
  // wander_factor times the expected displacement; the prior is then returned.
  bool wander_test = false;
  double wander_expected_m = 0.02;  // metres times length_unit_m (ARKit-grade room prior, §4.3)
  double wander_factor = 2.0;

  // Inconsistent-pairs test, beyond the paper (its §4.11 "Failure analysis": on repeated structure
  // image pairs match the wrong copy, and the filter-free objective keeps those matches and is
  // pulled off the truth): after the last pass, per image pair, the median over its used matches
  // of the symmetric epipolar distance restricted to positive ray times (per direction the
  // cross-projection residual minimized over the ray time, refine/checks/pair_consistency.h) at the
  // solved poses and intrinsics; a pair above inconsistent_pair_px is inconsistent, and the test
  // fires when more than max_inconsistent_pair_fraction of the pairs are. It reads neither the
  // prior, the ground truth nor the solved ray times (from 32° priors some end in the arctan's
  // flat tail, where the residual of a correct pair reaches 10^5 px). Flag only: the solution is
  // still returned (returning the prior is the trust region's job). 4 px lies between the correct
  // pairs' and the wrong pairs' measures on the shared scenes (docs/refine_options.md). 0.1
  // tolerates one bad pair in 10; the auto preset, whose wrong-pair removal runs first, tolerates
  // none (configs/presets/refine/auto.yaml says why).
  bool inconsistent_pairs_test = true;
  double inconsistent_pair_px = 4.0;  // pixels, per-pair median
  // The posterior test's threshold is max(inconsistent_pair_px, this x the median over the pairs of
  // their measure); 0 = inconsistent_pair_px alone. (The wrong-pair removal keeps the absolute
  // threshold: it separated castle-P19's wrong pairs at the basin solution.)
  double inconsistent_pair_median_multiple = 0.0;
  double max_inconsistent_pair_fraction = 0.1;  // of the pairs with used matches, in [0, 1)

  // The recipe of passes (one switch; it replaced the booleans `staged` and `basin_first`, still
  // accepted with a warning: DeprecatedAliases):
  // - "single": one pass with the options above, the GNC schedule from the prior (§3.5).
  // - "staged", the room recipe (§4.3): pass 1 = poses-only GNC from the prior with a light
  //   orientation anchor and capped matches (stage1_* below); pass 2 = one warm solve at the
  //   nominal scale with the options above (self-calibration, weights, cap), its priors
  //   re-anchored at the pass-1 poses.
  // - "basin_first" (the basin-first solve below).
  RefineRecipe recipe = RefineRecipe::kSingle;
  double stage1_orientation_weight = 10.0;  // λR of the staged recipe's pass 1, 1/rad²
  int stage1_max_matches_per_pair = 100;    // cap of the staged recipe's pass 1; 0 keeps all

  // Basin-first solve (recipe: basin_first; issue 12, the `auto` preset; built from §4.8 "Basin of
  // convergence" and §3.3): pass 1 = the basin solve, poses only, full GNC schedule, no orientation
  // prior and basin_max_matches_per_pair matches, which recovers priors tens of degrees off; pass 2
  // = the orientation-prior probe, one nominal-scale solve of the same matches from pass 1's
  // solution with λR = orientation_weight against the original prior's rotations; pass 3 = the
  // finish from the solution the probe keeps, one nominal-scale solve with max_matches_per_pair
  // matches and the self-calibration options. The probe decides λR of the finish from the data:
  // when pulling the rotations towards the prior raises the median cross-projection residual
  // (robust to the outliers, which saturate the arctan loss and dilute its mean) by more than
  // orientation_prior_max_increase, the matches contradict the prior's rotations
  // (a wrong prior, or a phone's rotation drift) and the finish runs with λR = 0 from pass 1;
  // otherwise the prior only fixes what the matches leave undetermined (the slow rotation drift a
  // long sweep's λR = 0 solve picks up at no cost) and the finish keeps it.
  int basin_max_matches_per_pair = 100;          // cap of passes 1 and 2; 0 keeps all
  double orientation_prior_max_increase = 0.05;  // relative rise of the median residual
  // Wrong-pair removal of the basin-first solve (issue 12; beyond the paper, cf. its §4.11
  // "Failure analysis"): after the basin solve every pair is judged at its solution (the
  // inconsistent-pairs test's per-pair measure against inconsistent_pair_px), and the basin is
  // solved again from the prior without the inconsistent ones, until the solution leaves exactly
  // those it was solved without above the threshold, at most this many times; the probe and the
  // finish then use the remaining pairs. A removal that would split the match graph is not made
  // (that pair stays; the images it alone holds fire loose_parts, refine/checks/loose_parts.h). The
  // threshold is the inconsistent-pairs test's (docs/refine_options.md).
  int max_pair_removal_rounds = 0;
  // Basin-first finish anneal (issue 12, beyond the paper's fixed nominal scale): after the
  // nominal-scale finish, one more pass (`finish_anneal`; the finish's λR, held towards the
  // finish's own rotations) continues the GNC schedule below loss_scale_px2 with one stage at
  // a = (k m)² px², where m is the basin solve's median cross-projection residual (px) and k this
  // multiple, at least 0.25 px² (keypoints are located to about half a pixel); 0 (or a not below
  // loss_scale_px2) = no such pass. At a = 100 px² a
  // wrong match 10-30 px off still pulls (weight 1/(1 + (r²/a)²) = 0.5-0.01); repeated structure
  // leaves such matches inside correct pairs (castle-P19), and a scale matched to the measured
  // noise discounts them while a capture with larger residuals keeps a wider scale.
  double finish_noise_multiple = 0.0;
  // The finish anneal's λR as a multiple of the finish's (its hold towards the finish's own
  // rotations). Any positive weight pins what the matches leave free (no drift: a null direction
  // of the match term costs them nothing); a weaker one lets the matches move what they do
  // constrain (measured for 0.01 and 1: docs/refine_options.md).
  double finish_anneal_hold_ratio = 1.0;
  // The track finish (issue 50, refine/recipes/track_finish.h): after the last pass, a bundle
  // adjustment with one point per track (the maximum-likelihood estimator under keypoint noise)
  // over the matches the ray-time solution explains, returned only when its residuals imply the
  // same keypoint noise and no frame moves more than track_finish_max_move_sigma times its
  // ray-time σ, the σ scaled up by the median frame's move (in σ) where that is above 1;
  // otherwise the ray-time solution stands and the summary says why. Fixed intrinsics only.
  // Two right estimators differ by less than either's spread under the noise model; on a phone
  // capture the model's σ is optimistic and every frame moves several of it (docs/efficiency.md),
  // while a frame pulled by wrong tracks moves far more than the others.
  bool track_finish = false;
  double track_finish_max_move_sigma = 5.0;

  // Frame checks after the solve (issue 46, refine/checks/frame_verdicts.h): a frame that moved far
  // more than the others and fits worse (refine/checks/frame_doubt.h; not for a prior whose
  // rotations came from the matches: its own errors are no independent measure), and a frame whose
  // matches other intrinsics explain far better (refine/checks/frame_intrinsics.h). A frame either
  // names is doubted.
  bool check_frame_doubts = true;
  FrameDoubtOptions frame_doubt;
  bool check_frame_intrinsics = true;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("parameterization", parameterization,
      "Structure variables: one ray time per observation (the method) or per track (§3.6 "
      "ablation)");
    v("loss_scale_px2", loss_scale_px2,
      "Arctan loss scale a of the nominal objective, px² (§3.3; between 0.01, below keypoint "
      "noise, and 1e8)",
      AtLeast(0.01), AtMost(1e8));
    v("gnc_scales", gnc_scales,
      "GNC schedule of arctan scales solved in order, px² (§3.5); loss_scale_px2 is appended "
      "last; [] = plain solve",
      AtLeast(0.01), AtMost(1e8));
    v("position_weight", position_weight,
      "λp, weight of the position prior per squared depth scale of the prior (§3.3; 1/m² at a "
      "1 m deep scene)",
      NonNegative(), AtMost(1e8));
    v("orientation_weight", orientation_weight,
      "λR, weight of the orientation prior, 1/rad² (§3.3)", NonNegative(), AtMost(1e12));
    v("gauge_orientation_weight", gauge_orientation_weight,
      "Weight of the prior's rotations when fitting the solution's global similarity after the "
      "solve, 1/rad² (0 = centres only)",
      NonNegative(), AtMost(1e12));
    v("uncertainty_max_cameras", uncertainty_max_cameras,
      "Per-camera pose uncertainty (σ of rotation and centre) up to this many cameras; 0 = off",
      NonNegative(), AtMost(1e5));
    v("ray_time_init", ray_time_init,
      "Ray-time start: per-image median closest-approach depth under the prior, or the constant "
      "below (§3.2)");
    v("ray_time_constant_m", ray_time_constant_m,
      "Start of every ray time with ray_time_init 'constant', prior length units (paper: 1 m)",
      Positive(), AtMost(1e9));
    v("max_matches_per_pair", max_matches_per_pair,
      "At most this many matches per image pair, drawn with a per-pair seed (§4.7: 100); 0 keeps "
      "all",
      NonNegative(), AtMost(1e7));
    v("match_cap_seed", match_cap_seed, "Seed of the per-pair match draw");
    v("refine_focal", refine_focal, "Self-calibrate the focal lengths fx, fy (§3.1, §4.3)");
    v("refine_principal_point", refine_principal_point,
      "Self-calibrate the principal point cx, cy (§3.1, §4.3)");
    v("refine_distortion", refine_distortion,
      "Self-calibrate the distortion k1, k2, p1, p2 (§3.1, §4.3)");
    v("intrinsics_sharing", intrinsics_sharing,
      "Self-calibration of several cameras: one set per camera, or one set for all images started "
      "at their median (§3.1, §4.6 focal drift)");
    v("use_evaluation_cache", use_evaluation_cache,
      "Shared evaluation cache: undistortion and ray points once per observation, once per solve "
      "when no intrinsic is refined (§3.7); false = automatic differentiation of every residual");
    v("solver", solver,
      "Solver per pass: the ray-time LM (closed-form ray-time elimination, intrinsics held), "
      "Ceres, or auto (the ray-time LM where no intrinsic is refined, else Ceres)");
    v("num_threads", num_threads, "Solver threads; 0 = hardware concurrency", NonNegative(),
      AtMost(1024));
    v("deterministic", deterministic,
      "Bit-identical results whatever the thread count (Ceres on one thread; the ray-time LM "
      "solver and the self-calibration cache parallel)");
    v("max_iterations", max_iterations, "Ceres iteration limit per GNC stage", Positive(),
      AtMost(1e5));
    v("function_tolerance", function_tolerance,
      "Relative cost-change tolerance of the GNC stage that gives the solution", Positive(),
      AtMost(1));
    v("intermediate_function_tolerance", intermediate_function_tolerance,
      "Relative cost-change tolerance of a GNC stage whose solution only starts another (earlier "
      "scales, the basin, the probe, a finish the anneal follows)",
      Positive(), AtMost(1));
    v("max_step_doublings", max_step_doublings,
      "Ray-time LM: doublings of an accepted step that beat the model's decrease by 1.5x, while "
      "the cost falls; 0 = off",
      NonNegative(), AtMost(60));
    v("trust_region", trust_region,
      "Return the prior when the solution moves a frame beyond the thresholds below (§3.6)");
    v("trust_region_rotation_deg", trust_region_rotation_deg,
      "Trust-region rotation threshold per frame, degrees (§3.6)", Positive(), AtMost(180));
    v("trust_region_translation_m", trust_region_translation_m,
      "Trust-region centre threshold per frame, metres at object scale x length_unit_m (§3.6)",
      Positive(), AtMost(1e9));
    v("length_unit_m", length_unit_m,
      "Scene length unit relative to metric object captures; scales the metre thresholds",
      Positive(), AtMost(1e9));
    v("wander_test", wander_test,
      "Return the prior when the Sim(3)-aligned median displacement exceeds wander_factor x "
      "expected (§4.3)");
    v("wander_expected_m", wander_expected_m,
      "Expected per-frame displacement of the wander test, metres x length_unit_m (§4.3)",
      Positive(), AtMost(1e9));
    v("wander_factor", wander_factor, "Wander test threshold as a multiple of the expected",
      Positive(), AtMost(1e9));
    v("inconsistent_pairs_test", inconsistent_pairs_test,
      "Flag a solution that leaves more than max_inconsistent_pair_fraction of pairs unexplained "
      "(cf. §4.11)");
    v("inconsistent_pair_px", inconsistent_pair_px,
      "A pair is inconsistent above this median positive-ray epipolar distance, pixels", Positive(),
      AtMost(1e6));
    v("inconsistent_pair_median_multiple", inconsistent_pair_median_multiple,
      "The test's pair threshold rises to this x the median pair's measure when that is higher; "
      "0 = inconsistent_pair_px alone",
      NonNegative(), AtMost(1e6));
    v("max_inconsistent_pair_fraction", max_inconsistent_pair_fraction,
      "Fraction of inconsistent pairs above which the test fires", NonNegative(), Below(1));
    v("recipe", recipe,
      "Passes: single (one), staged (§4.3 room recipe: a poses-only GNC pass, then a warm "
      "self-calibration pass) or basin_first (basin solve, orientation-prior probe, finish; §4.8, "
      "§3.3)");
    v("stage1_orientation_weight", stage1_orientation_weight,
      "λR of the staged recipe's first pass, 1/rad² (§4.3)", NonNegative(), AtMost(1e12));
    v("stage1_max_matches_per_pair", stage1_max_matches_per_pair,
      "Match cap of the staged recipe's first pass; 0 keeps all (§4.3)", NonNegative(),
      AtMost(1e7));
    v("basin_max_matches_per_pair", basin_max_matches_per_pair,
      "Match cap of the basin solve and the orientation-prior probe; 0 keeps all (§4.7: 100)",
      NonNegative(), AtMost(1e7));
    v("orientation_prior_max_increase", orientation_prior_max_increase,
      "Relative rise of the median residual under the orientation prior above which the finish "
      "drops it",
      NonNegative(), AtMost(1e6));
    v("finish_noise_multiple", finish_noise_multiple,
      "Basin-first: after the finish, a pass at arctan scale (this x the basin's median residual)² "
      "px², rotations held at the finish's; 0 = none",
      NonNegative(), AtMost(1e6));
    v("finish_anneal_hold_ratio", finish_anneal_hold_ratio,
      "The finish anneal's λR towards the finish's rotations, as a multiple of the finish's λR",
      NonNegative(), AtMost(1e6));
    v("track_finish", track_finish,
      "After the last pass, a bundle adjustment with one point per track on the matches the "
      "solution explains, kept only when its own check passes (fixed intrinsics)");
    v("track_finish_max_move_sigma", track_finish_max_move_sigma,
      "The track finish is rejected when a frame moves more than this many of its ray-time σ "
      "(times the median frame's move in σ, when above 1)",
      Positive(), AtMost(1e6));
    v("check_frame_doubts", check_frame_doubts,
      "Doubt frames that moved far more than the others and fit their matches worse (wrong "
      "intrinsics, a frame the solve could not place); not for a prior made from the match graph");
    frame_doubt.VisitFields(v);  // flat keys: frame_doubt_residual_ratio, ...
    v("check_frame_intrinsics", check_frame_intrinsics,
      "Doubt frames whose matches another focal length or principal point explains far better");
    v("max_pair_removal_rounds", max_pair_removal_rounds,
      "Basin-first: times the pairs the basin solve leaves above inconsistent_pair_px are removed "
      "and the basin solve rerun; 0 keeps every pair",
      NonNegative(), AtMost(1000));
  }

  // The keys `recipe` replaced (core/options.h OptionAlias: `staged: true` is `recipe: staged`).
  static std::vector<OptionAlias> DeprecatedAliases() {
    return {{"staged", "recipe", "staged"}, {"basin_first", "recipe", "basin_first"}};
  }

  // Fixed intrinsics are each image's own: a shared set exists only to be refined.
  void CheckRelations(const Requirement& require) const {
    require(intrinsics_sharing != IntrinsicsSharing::kShared || SelfCalibrates(),
            "intrinsics_sharing 'shared' replaces the images' cameras by one set of intrinsics "
            "to self-calibrate, so it needs refine_focal, refine_principal_point or "
            "refine_distortion; with fixed intrinsics every image uses its own camera as given "
            "(intrinsics_sharing: per_camera)");
    require(finish_noise_multiple == 0 || recipe == RefineRecipe::kBasinFirst,
            "finish_noise_multiple needs recipe: basin_first (the finish anneals from the basin "
            "solve)");
    require(max_pair_removal_rounds == 0 || recipe == RefineRecipe::kBasinFirst,
            "max_pair_removal_rounds needs recipe: basin_first (the pairs are judged at the basin "
            "solve)");
    require(solver != RefineSolver::kRayTimeLm || !SelfCalibrates(),
            "solver 'ray_time_lm' holds every intrinsic; self-calibration (refine_focal, "
            "refine_principal_point, refine_distortion) needs solver 'ceres' or 'auto'");
    // The cache is Ceres' residual evaluation; turning it off used to switch an auto solve to
    // Ceres silently.
    require(use_evaluation_cache || solver == RefineSolver::kCeres ||
                (solver == RefineSolver::kAuto && SelfCalibrates()),
            "use_evaluation_cache: false changes how Ceres evaluates its residuals (automatic "
            "differentiation of each), and solver '" +
                std::string(NameOf(solver)) +
                "' runs no Ceres pass here: set solver: ceres to compare the two evaluations");
  }

  // True when any intrinsic is refined.
  bool SelfCalibrates() const {
    return refine_focal || refine_principal_point || refine_distortion;
  }
  // The loss scales of the stages actually solved (gnc_scales, then loss_scale_px2 if absent).
  std::vector<double> StageScales() const;
  // Threads to use (num_threads, or the hardware concurrency for 0).
  int Threads() const;
};

}  // namespace raytime
