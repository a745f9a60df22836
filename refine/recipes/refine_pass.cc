#include "refine/recipes/refine_pass.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "core/statistics.h"
#include "core/timing.h"
#include "refine/checks/pair_consistency.h"
#include "refine/checks/pose_uncertainty.h"
#include "refine/solve/ceres_gnc.h"
#include "refine/solve/gauge_polish.h"
#include "refine/solve/ray_geometry.h"
#include "refine/solve/ray_time_init.h"
#include "refine/solve/ray_time_lm_solver.h"
#include "refine/solve/ray_time_problem.h"

namespace raytime {
namespace {

// How far (rotation, after the mean rotation between the two) an earlier run's pose may be from
// this run's start of a pass for the pass to start from it (RefineWarmStart). The capped passes'
// solution and the earlier finish differed by 0.15° at most on the grown chair.
constexpr double kMaxWarmStartRotationDeg = 0.5;

uint64_t KeyOf(const LayoutObservation& obs) { return WarmRayTimeKey(obs.image, obs.keypoint); }

// Norms of the cross-projection residuals π_target(X_source) − û_target (paper eqs. rij, rji)
// at the given poses, intrinsics blocks and ray times (indexed as layout.ray_time_observation),
// pixels, one per layout residual.
std::vector<double> ResidualNorms(const RefineInput& input, const ProblemLayout& layout,
                                  const std::vector<Rigid3>& world_from_cam,
                                  const CameraBlocks& cameras,
                                  const std::vector<double>& ray_times) {
  std::vector<std::array<double, kPoseBlockSize>> poses(world_from_cam.size());
  for (size_t i = 0; i < world_from_cam.size(); ++i)
    ToPoseBlock(world_from_cam[i], poses[i].data());
  const auto undistorted = [&](const LayoutObservation& obs) {
    const double pixel[2] = {input.keypoints[obs.image](obs.keypoint, 0),
                             input.keypoints[obs.image](obs.keypoint, 1)};
    Eigen::Vector2d u;
    UndistortPixel(cameras.Of(obs.image).params.data(), pixel, u.data());
    return u;
  };
  std::vector<double> norms;
  norms.reserve(layout.residuals.size());
  for (const CrossProjection& residual : layout.residuals) {
    const LayoutObservation& source = layout.observations[residual.source];
    const LayoutObservation& target = layout.observations[residual.target];
    const Eigen::Vector2d u_source = undistorted(source);
    Eigen::Vector3d point;
    RayPointInWorld(cameras.Of(source.image).params.data(), poses[source.image].data(),
                    ray_times[source.ray_time], u_source.data(), point.data());
    const Eigen::Vector2d u_target = undistorted(target);
    Eigen::Vector2d r;
    TargetResidualAtPose(cameras.Of(target.image).params.data(), poses[target.image].data(),
                         point.data(), u_target.data(), r.data());
    norms.push_back(r.norm());
  }
  return norms;
}

// The fixed-intrinsics problem for the ray-time LM solver: what RayTimeProblem gives Ceres with
// FixedIntrinsicsCrossProjectionCost (the same undistorted pixels and unit rays, computed once;
// the same weights), residuals ordered by ray time.
RayTimeLmProblem BuildRayTimeLmProblem(const RefineInput& input, const ProblemLayout& layout,
                                       const std::vector<Rigid3>& prior_world_from_cam,
                                       const std::vector<Rigid3>& initial_world_from_cam,
                                       const CameraBlocks& cameras, double position_weight,
                                       double orientation_weight, std::vector<double> ray_times) {
  RayTimeLmProblem problem;
  const int num_images = static_cast<int>(initial_world_from_cam.size());
  problem.world_from_cam = initial_world_from_cam;
  const std::vector<bool> observed = ObservedImages(layout, num_images);
  problem.held.resize(num_images);
  for (int i = 0; i < num_images; ++i) problem.held[i] = !observed[i];
  problem.ray_times = std::move(ray_times);
  problem.pinhole.resize(num_images);
  for (int i = 0; i < num_images; ++i) {
    const auto& p = cameras.Of(i).params;
    problem.pinhole[i] << p[kFx], p[kFy], p[kCx], p[kCy];
  }
  const ObservationRays fixed = FixedObservationRays(input, layout, cameras);
  // Grouped by ray time, in layout order within each: a counting sort, the order std::stable_sort
  // gives (its merges were 1 % of a refine's samples), each residual written once into its place.
  std::vector<size_t> next(problem.ray_times.size() + 1, 0);
  for (const CrossProjection& residual : layout.residuals) {
    ++next[layout.observations[residual.source].ray_time + 1];
  }
  for (size_t t = 1; t < next.size(); ++t) next[t] += next[t - 1];
  problem.residuals.resize(layout.residuals.size());
  for (const CrossProjection& residual : layout.residuals) {
    const LayoutObservation& source = layout.observations[residual.source];
    RayTimeLmResidual& r = problem.residuals[next[source.ray_time]++];
    r.source_image = source.image;
    r.ray_time = source.ray_time;
    r.target_image = layout.observations[residual.target].image;
    r.source_ray = fixed.rays[residual.source];
    r.target_undistorted = fixed.undistorted[residual.target];
    r.source_observation = residual.source;
    r.target_observation = residual.target;
  }
  const int num_scalar_residuals = 2 * static_cast<int>(layout.residuals.size());
  problem.match_loss_weight = num_scalar_residuals > 0 ? 2.0 / num_scalar_residuals : 0.0;
  problem.prior_world_from_cam = prior_world_from_cam;
  problem.position_weight = position_weight / num_images;
  problem.orientation_weight = orientation_weight / num_images;
  return problem;
}

// 1. The poses of an earlier run's solution at this pass (issue 34), where they agree with this
// run's own start (the capped passes' solution) after the mean rotation between the two: an
// earlier solution of another problem (another prior, other matches) never takes the solve where
// the recipe would not. Returns which images start from it (their ray times too).
std::vector<bool> StartFromEarlierRun(const RefineInput& input, const PassSettings& settings,
                                      PassState* state, RefinePassSummary* pass,
                                      double* largest_difference_deg, int* num_too_far) {
  std::vector<bool> from_earlier_run(state->world_from_cam.size(), false);
  const auto warm = settings.warm_startable ? input.warm_start.world_from_cam.find(settings.name)
                                            : input.warm_start.world_from_cam.end();
  if (warm == input.warm_start.world_from_cam.end()) return from_earlier_run;
  // Two solves of one problem may differ by a gauge rotation (each is held to the prior only
  // weakly): the differences are judged after the mean one.
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (size_t i = 0; i < warm->second.size() && i < state->world_from_cam.size(); ++i) {
    if (!warm->second[i]) continue;
    Eigen::Quaterniond d = warm->second[i]->rotation * state->world_from_cam[i].rotation.inverse();
    if (d.w() < 0) d.coeffs() = -d.coeffs();
    sum += d.coeffs();
  }
  const Eigen::Quaterniond gauge =
      sum.norm() > 0 ? Eigen::Quaterniond(sum.normalized()) : Eigen::Quaterniond::Identity();
  for (size_t i = 0; i < warm->second.size() && i < state->world_from_cam.size(); ++i) {
    if (!warm->second[i]) continue;
    const double difference_deg =
        RotationDistance(warm->second[i]->rotation, gauge * state->world_from_cam[i].rotation) *
        180.0 / M_PI;
    if (!(difference_deg <= kMaxWarmStartRotationDeg)) {
      ++*num_too_far;
      continue;
    }
    *largest_difference_deg = std::max(*largest_difference_deg, difference_deg);
    state->world_from_cam[i] = *warm->second[i];
    from_earlier_run[i] = true;
    ++pass->ray_time_init.num_images_from_earlier_run;
  }
  return from_earlier_run;
}

// 2. Every ray time's start: the initialization (§3.2), then the value an earlier pass solved,
// or an earlier run's where its image starts from that run, and in the basin-first finish the
// ones the earlier passes' cap left out at their closest approach at the solved poses.
std::vector<double> StartRayTimes(const RefineInput& input, const RefineOptions& options,
                                  const PassSettings& settings, bool warm_started,
                                  const std::vector<bool>& from_earlier_run,
                                  double largest_difference_deg, int num_too_far, PassState* state,
                                  RefinePassSummary* pass) {
  const ProblemLayout& layout = state->layout;
  std::vector<double> ray_times =
      InitialRayTimes(layout, input, state->world_from_cam, state->cameras, options.ray_time_init,
                      options.ray_time_constant_m, &pass->ray_time_init);
  std::vector<bool> unsolved(ray_times.size(), true);
  for (size_t t = 0; t < ray_times.size(); ++t) {
    const auto it = state->ray_time_by_observation.find(
        KeyOf(layout.observations[layout.ray_time_observation[t]]));
    if (it == state->ray_time_by_observation.end()) continue;
    ray_times[t] = it->second;
    unsolved[t] = false;
    ++pass->ray_time_init.num_warm_started;
  }
  if (warm_started) {
    for (size_t t = 0; t < ray_times.size(); ++t) {
      const LayoutObservation& obs = layout.observations[layout.ray_time_observation[t]];
      if (!from_earlier_run[obs.image]) continue;
      const auto it = input.warm_start.ray_times.find(KeyOf(obs));
      if (it == input.warm_start.ray_times.end()) continue;
      ray_times[t] = it->second;
      if (unsolved[t]) ++pass->ray_time_init.num_warm_started;
      unsolved[t] = false;
      ++pass->ray_time_init.num_ray_times_from_earlier_run;
    }
    spdlog::info(fmt::format(
        "refine: {}: started from the previous run's solution: {} of {} images (at most {:.3f}° "
        "from this run's start after their mean rotation{}), {} of {} ray times",
        settings.name, pass->ray_time_init.num_images_from_earlier_run,
        state->world_from_cam.size(), largest_difference_deg,
        num_too_far == 0 ? std::string()
                         : fmt::format("; {} further than {}° started as without it", num_too_far,
                                       kMaxWarmStartRotationDeg),
        pass->ray_time_init.num_ray_times_from_earlier_run, ray_times.size()));
  }
  if (settings.start_unsolved_at_closest_approach && pass->ray_time_init.num_warm_started > 0) {
    pass->ray_time_init.num_closest_approach_started = StartRayTimesAtClosestApproach(
        layout, input, state->world_from_cam, state->cameras, unsolved, &ray_times);
  }
  return ray_times;
}

// The problem's size in the summary and its log line, once it is built.
void RecordBuild(const RefineInput& input, const ProblemLayout& layout,
                 std::chrono::steady_clock::time_point build_start, RefinePassSummary* pass) {
  pass->build_seconds = SecondsSince(build_start);
  pass->num_cameras = static_cast<int>(input.prior_world_from_cam.size());
  pass->num_observations = static_cast<int>(layout.observations.size());
  pass->num_ray_times = static_cast<int>(layout.ray_time_observation.size());
  pass->num_tracks = layout.num_tracks;
  pass->num_matches_input = layout.num_matches_input;
  pass->num_matches_used = layout.num_matches_used;
  pass->num_residuals = static_cast<int>(layout.residuals.size());
  spdlog::info(
      fmt::format("refine: {}: {} cameras, {} of {} matches, {} residuals, {} ray times ({} init, "
                  "median depth {:.3g}), built in {:.2f} s, solver {}",
                  pass->name, pass->num_cameras, pass->num_matches_used, pass->num_matches_input,
                  pass->num_residuals, pass->num_ray_times, pass->ray_time_init.mode,
                  pass->ray_time_init.median_depth, pass->build_seconds, pass->solver));
}

// The GNC schedule of the pass (§3.5), whichever back-end runs it.
GncSettings GncSettingsOf(const RefineOptions& options, const PassSettings& settings) {
  GncSettings gnc;
  gnc.scales = settings.scales;
  gnc.max_iterations = options.max_iterations;
  gnc.function_tolerance = options.function_tolerance;
  gnc.intermediate_function_tolerance = options.intermediate_function_tolerance;
  gnc.ends_solve = !settings.intermediate;
  gnc.max_step_doublings = options.max_step_doublings;
  return gnc;
}

// 3a. The pass on the ray-time LM (every intrinsic held): built, solved; returns the solved ray
// times, `camera_observed` the cameras the problem does not hold.
std::vector<double> SolveOnRayTimeLm(const RefineInput& input, const RefineOptions& options,
                                     const PassSettings& settings,
                                     const std::vector<Rigid3>& anchor,
                                     std::vector<double> ray_times,
                                     std::chrono::steady_clock::time_point build_start,
                                     std::vector<bool>* camera_observed, PassState* state,
                                     RefinePassSummary* pass) {
  const ProblemLayout& layout = state->layout;
  RayTimeLmProblem problem = BuildRayTimeLmProblem(
      input, layout, anchor, state->world_from_cam, state->cameras, options.position_weight,
      settings.orientation_weight, std::move(ray_times));
  for (const bool held : problem.held) camera_observed->push_back(!held);
  RecordBuild(input, layout, build_start, pass);
  const auto solve_start = std::chrono::steady_clock::now();
  GncSettings gnc = GncSettingsOf(options, settings);
  gnc.residual_norms = [&] {
    return ResidualNorms(input, layout, problem.world_from_cam, state->cameras, problem.ray_times);
  };
  gnc.num_threads = options.Threads();
  pass->stages = SolveGncRayTimeLm(&problem, gnc);
  // The eliminated group is every ray time (§3.4), by construction.
  pass->elimination_group_size = pass->num_ray_times;
  state->world_from_cam = problem.world_from_cam;
  pass->solve_seconds = SecondsSince(solve_start);
  return std::move(problem.ray_times);
}

// 3b. The pass on Ceres (the passes that self-calibrate, or solver: ceres).
std::vector<double> SolveOnCeres(const RefineInput& input, const RefineOptions& options,
                                 const PassSettings& settings, const std::vector<Rigid3>& anchor,
                                 const std::vector<double>& ray_times,
                                 std::chrono::steady_clock::time_point build_start,
                                 std::vector<bool>* camera_observed, PassState* state,
                                 RefinePassSummary* pass) {
  const ProblemLayout& layout = state->layout;
  RayTimeProblemSettings problem_settings;
  problem_settings.position_weight = options.position_weight;
  problem_settings.orientation_weight = settings.orientation_weight;
  problem_settings.loss_scale_px2 = settings.scales.front();
  problem_settings.refine_focal = settings.refine_focal;
  problem_settings.refine_principal_point = settings.refine_principal_point;
  problem_settings.refine_distortion = settings.refine_distortion;
  problem_settings.use_evaluation_cache = options.use_evaluation_cache;
  problem_settings.num_threads = options.Threads();
  RayTimeProblem problem(input, layout, anchor, state->world_from_cam, state->cameras, ray_times,
                         problem_settings);
  *camera_observed = problem.camera_observed();
  RecordBuild(input, layout, build_start, pass);
  const auto solve_start = std::chrono::steady_clock::now();
  GncSettings gnc = GncSettingsOf(options, settings);
  gnc.residual_norms = [&] {
    CameraBlocks cameras = state->cameras;
    cameras.cameras = problem.Intrinsics();
    return ResidualNorms(input, layout, problem.WorldFromCam(), cameras, problem.ray_times());
  };
  gnc.num_threads = options.deterministic ? 1 : options.Threads();
  pass->stages = SolveGncWithCeres(&problem, gnc, &pass->elimination_group_size);
  state->world_from_cam = problem.WorldFromCam();
  state->cameras.cameras = problem.Intrinsics();
  pass->solve_seconds = SecondsSince(solve_start);
  return problem.ray_times();
}

// 4. The residuals at the solution: per image their median (the frame checks), and the pass's
// median, 90th percentile and mean match term at the nominal scale (loss_scale_px2, whatever the
// pass's own: the basin-first probe compares passes by it), logged.
void MeasureResiduals(const RefineInput& input, const RefineOptions& options,
                      const std::vector<double>& solved_ray_times, PassState* state,
                      RefinePassSummary* pass) {
  const ProblemLayout& layout = state->layout;
  std::vector<double> norms =
      ResidualNorms(input, layout, state->world_from_cam, state->cameras, solved_ray_times);
  std::vector<std::vector<double>> by_image(input.prior_world_from_cam.size());
  for (size_t r = 0; r < norms.size(); ++r) {
    by_image[layout.observations[layout.residuals[r].target].image].push_back(norms[r]);
  }
  state->image_residual_median_px.clear();
  for (const auto& image_norms : by_image) {
    state->image_residual_median_px.push_back(
        Median(image_norms, std::numeric_limits<double>::quiet_NaN()));
  }
  double loss_sum = 0.0;
  for (const double norm : norms) {
    loss_sum += options.loss_scale_px2 * std::atan(norm * norm / options.loss_scale_px2);
  }
  pass->match_cost_px2 = norms.empty() ? 0.0 : loss_sum / static_cast<double>(norms.size());
  pass->residual_median_px = Median(norms, 0.0);
  if (!norms.empty()) {
    const size_t rank = (norms.size() * 9 + 9) / 10 - 1;  // nearest rank: ceil(0.9 n) - 1
    std::nth_element(norms.begin(), norms.begin() + rank, norms.end());
    pass->residual_p90_px = norms[rank];
  }
  spdlog::info(fmt::format(
      "refine: {}: residuals at the solution: median {:.3g} px, 90th percentile {:.3g} px, mean "
      "match term {:.4g} px²",
      pass->name, pass->residual_median_px, pass->residual_p90_px, pass->match_cost_px2));
}

}  // namespace

PassSettings NominalPass(const RefineOptions& options) {
  PassSettings nominal;
  nominal.name = "solve";
  nominal.max_matches_per_pair = options.max_matches_per_pair;
  nominal.orientation_weight = options.orientation_weight;
  nominal.scales = options.StageScales();
  nominal.refine_focal = options.refine_focal;
  nominal.refine_principal_point = options.refine_principal_point;
  nominal.refine_distortion = options.refine_distortion;
  nominal.warm_startable = true;
  return nominal;
}

RefinePassSummary RunPass(const RefineInput& input, const RefineOptions& options,
                          const PassSettings& settings, const std::vector<Rigid3>& anchor,
                          PassState* state) {
  RefinePassSummary pass;
  pass.name = settings.name;
  pass.orientation_weight = settings.orientation_weight;
  pass.self_calibration =
      settings.refine_focal || settings.refine_principal_point || settings.refine_distortion;
  // The back-end, chosen once: the ray-time LM holds every intrinsic.
  const bool on_ray_time_lm = options.solver == RefineSolver::kRayTimeLm ||
                              (options.solver == RefineSolver::kAuto && !pass.self_calibration);
  pass.solver = NameOf(on_ray_time_lm ? RefineSolver::kRayTimeLm : RefineSolver::kCeres);
  const auto build_start = std::chrono::steady_clock::now();
  // 1.
  double largest_difference_deg = 0.0;
  int num_too_far = 0;
  const bool warm_started =
      settings.warm_startable && input.warm_start.world_from_cam.count(settings.name) > 0;
  const std::vector<bool> from_earlier_run =
      StartFromEarlierRun(input, settings, state, &pass, &largest_difference_deg, &num_too_far);
  // 2.
  state->layout =
      options.parameterization == RayTimeParameterization::kAnchored
          ? BuildAnchoredLayout(input, settings.max_matches_per_pair, options.match_cap_seed)
          : BuildPerObservationLayout(input, settings.max_matches_per_pair, options.match_cap_seed);
  std::vector<double> ray_times =
      StartRayTimes(input, options, settings, warm_started, from_earlier_run,
                    largest_difference_deg, num_too_far, state, &pass);
  // 3.
  std::vector<bool> camera_observed;
  std::vector<double> solved_ray_times =
      on_ray_time_lm ? SolveOnRayTimeLm(input, options, settings, anchor, std::move(ray_times),
                                        build_start, &camera_observed, state, &pass)
                     : SolveOnCeres(input, options, settings, anchor, ray_times, build_start,
                                    &camera_observed, state, &pass);
  // 4. The gauge (a similarity: the residuals are the solve's), the solved ray times kept for
  // the later passes, the residuals.
  pass.gauge_polish =
      PolishGauge(anchor, camera_observed, options.position_weight, settings.orientation_weight,
                  options.gauge_orientation_weight, &state->world_from_cam, &solved_ray_times);
  for (size_t t = 0; t < solved_ray_times.size(); ++t) {
    state->ray_time_by_observation[KeyOf(
        state->layout.observations[state->layout.ray_time_observation[t]])] = solved_ray_times[t];
  }
  MeasureResiduals(input, options, solved_ray_times, state, &pass);
  state->pass_world_from_cam[settings.name] = state->world_from_cam;
  state->anchor = anchor;
  return pass;
}

PoseUncertaintySummary PoseUncertaintyOf(const RefineInput& input, const RefineOptions& options,
                                         const PassState& state, const RefinePassSummary& last,
                                         const std::vector<Rigid3>& prior) {
  PoseUncertaintySummary off;
  if (options.uncertainty_max_cameras == 0) {
    off.reason = "off (uncertainty_max_cameras: 0)";
    return off;
  }
  if (last.self_calibration) {
    off.reason = "the last pass self-calibrated (the intrinsics' uncertainty is not modelled)";
    return off;
  }
  const ProblemLayout& layout = state.layout;
  std::vector<double> ray_times(layout.ray_time_observation.size(), 0.0);
  for (size_t t = 0; t < ray_times.size(); ++t) {
    ray_times[t] = state.ray_time_by_observation.at(
        KeyOf(layout.observations[layout.ray_time_observation[t]]));
  }
  // The prior terms only hold the gauge (projected onto the polish's below) and curve the shape by
  // some 1e-7 of the match term: the input prior and the last pass's weights.
  const RayTimeLmProblem problem =
      BuildRayTimeLmProblem(input, layout, prior, state.world_from_cam, state.cameras,
                            options.position_weight, last.orientation_weight, std::move(ray_times));
  PoseUncertaintySettings settings;
  settings.scale_px2 = last.stages.back().loss_scale_px2;
  settings.gauge_position_weight = options.position_weight;
  settings.gauge_orientation_weight = options.gauge_orientation_weight;
  settings.max_cameras = options.uncertainty_max_cameras;
  settings.num_threads = options.Threads();
  return EstimatePoseUncertainty(problem, settings);
}

SolvedObservations SolvedObservationsOf(const PassState& state) {
  const ProblemLayout& layout = state.layout;
  SolvedObservations out;
  const auto n = static_cast<Eigen::Index>(layout.observations.size());
  out.observations.resize(n, 2);
  out.ray_times.setConstant(n, std::numeric_limits<double>::quiet_NaN());
  for (Eigen::Index o = 0; o < n; ++o) {
    const LayoutObservation& obs = layout.observations[o];
    out.observations.row(o) << obs.image, obs.keypoint;
    if (obs.ray_time >= 0) out.ray_times(o) = state.ray_time_by_observation.at(KeyOf(obs));
  }
  out.matches.resize(static_cast<Eigen::Index>(layout.matches.size()), 2);
  for (size_t m = 0; m < layout.matches.size(); ++m) {
    out.matches.row(static_cast<Eigen::Index>(m)) << layout.matches[m].observation1,
        layout.matches[m].observation2;
  }
  return out;
}

std::vector<PairResidual> PairResidualsAt(const RefineInput& input, const ProblemLayout& layout,
                                          const std::vector<Rigid3>& world_from_cam,
                                          const CameraBlocks& cameras) {
  const int num_observations = static_cast<int>(layout.observations.size());
  Eigen::VectorXi images(num_observations);
  Keypoints pixels(num_observations, 2);
  for (int o = 0; o < num_observations; ++o) {
    const LayoutObservation& obs = layout.observations[o];
    images(o) = obs.image;
    pixels.row(o) = input.keypoints[obs.image].row(obs.keypoint);
  }
  std::vector<int> count(input.pairs.size(), 0);
  for (const LayoutMatch& match : layout.matches) ++count[match.pair];
  std::vector<PairObservationMatches> pairs;
  std::vector<int> slot(input.pairs.size(), -1);
  for (size_t p = 0; p < input.pairs.size(); ++p) {
    if (count[p] == 0) continue;
    slot[p] = static_cast<int>(pairs.size());
    PairObservationMatches pair;
    pair.image1 = input.pairs[p].image1;
    pair.image2 = input.pairs[p].image2;
    pair.observations.resize(count[p], 2);
    pairs.push_back(std::move(pair));
  }
  std::vector<int> filled(pairs.size(), 0);
  for (const LayoutMatch& match : layout.matches) {
    const int s = slot[match.pair];
    pairs[s].observations.row(filled[s]++) << match.observation1, match.observation2;
  }
  std::vector<IntrinsicsVector> image_intrinsics;
  for (size_t i = 0; i < input.prior_world_from_cam.size(); ++i) {
    image_intrinsics.emplace_back(cameras.Of(static_cast<int>(i)).params.data());
  }
  return PairResidualMedians(image_intrinsics, world_from_cam, images, pixels, pairs);
}

std::vector<PairResidual> SolvedPairResiduals(const RefineInput& input, const PassState& state) {
  return PairResidualsAt(input, state.layout, state.world_from_cam, state.cameras);
}

void CountBlocks(const PassState& state, CameraBlocksSummary* summary) {
  std::vector<int> observations(state.cameras.cameras.size(), 0);
  for (const LayoutObservation& obs : state.layout.observations) {
    ++observations[state.cameras.camera_of_image[obs.image]];
  }
  summary->num_blocks = 0;
  summary->min_block_observations = 0;
  for (const int count : observations) {
    if (count == 0) continue;
    summary->min_block_observations =
        summary->num_blocks == 0 ? count : std::min(summary->min_block_observations, count);
    ++summary->num_blocks;
  }
}

}  // namespace raytime
