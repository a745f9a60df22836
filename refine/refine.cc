// RefinePoses: one pass (or the two passes of the staged room recipe, §4.3, or the three of the
// basin-first solve) of layout → ray-time
// initialization → problem → GNC → gauge polish, then the posterior guardrails (§3.6, §4.3, and
// the inconsistent-pairs test beyond the paper).
#include "refine/refine.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>

#include "core/error.h"
#include "core/graph.h"
#include "core/options.h"
#include "core/statistics.h"
#include "core/timing.h"
#include "refine/camera_blocks.h"
#include "refine/gauge_polish.h"
#include "refine/gnc_solver.h"
#include "refine/guardrails.h"
#include "refine/pair_consistency.h"
#include "refine/problem_layout.h"
#include "refine/ray_geometry.h"
#include "refine/ray_time_init.h"
#include "refine/ray_time_lm_solver.h"
#include "refine/ray_time_problem.h"

namespace raytime {
namespace {

std::vector<std::string> Labels(const RefineInput& input, const std::vector<int>& images) {
  std::vector<std::string> labels;
  for (const int image : images) labels.push_back(input.Label(image));
  return labels;
}

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

uint64_t KeyOf(const LayoutObservation& obs) {
  return (static_cast<uint64_t>(obs.image) << 32) | static_cast<uint32_t>(obs.keypoint);
}

// Norms of the cross-projection residuals π_target(X_source) − û_target (paper eqs. rij, rji)
// at the given poses, intrinsics blocks and ray times (indexed as layout.ray_time_observation),
// pixels, one per layout residual.
std::vector<double> ResidualNorms(const RefineInput& input, const ProblemLayout& layout,
                                  const std::vector<Rigid3>& world_from_cam,
                                  const CameraBlocks& cameras,
                                  const std::vector<double>& ray_times) {
  std::vector<std::array<double, kPoseBlockSize>> poses(world_from_cam.size());
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    const Eigen::Quaterniond q = world_from_cam[i].rotation.normalized();
    const Eigen::Vector3d& c = world_from_cam[i].translation;
    poses[i] = {q.x(), q.y(), q.z(), q.w(), c.x(), c.y(), c.z()};
  }
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
    Eigen::Vector2d projected;
    ProjectWorldPoint(cameras.Of(target.image).params.data(), poses[target.image].data(),
                      point.data(), projected.data());
    norms.push_back((projected - undistorted(target)).norm());
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
  problem.residuals.reserve(layout.residuals.size());
  for (const CrossProjection& residual : layout.residuals) {
    const LayoutObservation& source = layout.observations[residual.source];
    RayTimeLmResidual r;
    r.source_image = source.image;
    r.ray_time = source.ray_time;
    r.target_image = layout.observations[residual.target].image;
    r.source_ray = fixed.rays[residual.source];
    r.target_undistorted = fixed.undistorted[residual.target];
    problem.residuals.push_back(r);
  }
  std::stable_sort(problem.residuals.begin(), problem.residuals.end(),
                   [](const RayTimeLmResidual& a, const RayTimeLmResidual& b) {
                     return a.ray_time < b.ray_time;
                   });
  const int num_scalar_residuals = 2 * static_cast<int>(layout.residuals.size());
  problem.match_loss_weight = num_scalar_residuals > 0 ? 2.0 / num_scalar_residuals : 0.0;
  problem.prior_world_from_cam = prior_world_from_cam;
  problem.position_weight = position_weight / num_images;
  problem.orientation_weight = orientation_weight / num_images;
  return problem;
}

// What differs between the passes of one run.
struct PassSettings {
  std::string name;
  int max_matches_per_pair = 0;
  double orientation_weight = 0.0;
  std::vector<double> scales;
  bool refine_focal = false;
  bool refine_principal_point = false;
  bool refine_distortion = false;
  bool start_unsolved_at_closest_approach = false;  // StartRayTimesAtClosestApproach
};

// State carried from one pass to the next (the staged recipe's warm start), and the last pass's
// layout (its used matches) for the inconsistent-pairs test.
struct PassState {
  std::vector<Rigid3> world_from_cam;
  CameraBlocks cameras;  // the intrinsics blocks, at their current values
  std::unordered_map<uint64_t, double> ray_time_by_observation;  // keyed by (image, keypoint)
  ProblemLayout layout;
};

RefinePassSummary RunPass(const RefineInput& input, const RefineOptions& options,
                          const PassSettings& settings, const std::vector<Rigid3>& anchor,
                          PassState* state) {
  RefinePassSummary pass;
  pass.name = settings.name;
  pass.orientation_weight = settings.orientation_weight;
  pass.self_calibration =
      settings.refine_focal || settings.refine_principal_point || settings.refine_distortion;
  const auto build_start = std::chrono::steady_clock::now();
  state->layout =
      options.parameterization == "anchored"
          ? BuildAnchoredLayout(input, settings.max_matches_per_pair, options.match_cap_seed)
          : BuildPerObservationLayout(input, settings.max_matches_per_pair, options.match_cap_seed);
  const ProblemLayout& layout = state->layout;
  std::vector<double> ray_times =
      InitialRayTimes(layout, input, state->world_from_cam, state->cameras, options.ray_time_init,
                      options.ray_time_constant_m, &pass.ray_time_init);
  // A later pass starts every ray time an earlier pass solved from its solved value ...
  std::vector<bool> unsolved(ray_times.size(), true);
  for (size_t t = 0; t < ray_times.size(); ++t) {
    const auto it = state->ray_time_by_observation.find(
        KeyOf(layout.observations[layout.ray_time_observation[t]]));
    if (it == state->ray_time_by_observation.end()) continue;
    ray_times[t] = it->second;
    unsolved[t] = false;
    ++pass.ray_time_init.num_warm_started;
  }
  // ... and, in the basin-first finish, the ones the earlier passes' cap left out at their own
  // closest approach at the solved poses.
  if (settings.start_unsolved_at_closest_approach && pass.ray_time_init.num_warm_started > 0) {
    pass.ray_time_init.num_closest_approach_started = StartRayTimesAtClosestApproach(
        layout, input, state->world_from_cam, state->cameras, unsolved, &ray_times);
  }

  const bool self_calibration = pass.self_calibration;
  pass.solver = options.solver == "ray_time_lm" || (options.solver == "auto" && !self_calibration)
                    ? "ray_time_lm"
                    : "ceres";
  std::vector<double> solved_ray_times;
  std::vector<bool> camera_observed;
  std::optional<RayTimeLmProblem> lm_problem;
  std::optional<RayTimeProblem> ceres_problem;
  if (pass.solver == "ray_time_lm") {
    lm_problem.emplace(BuildRayTimeLmProblem(input, layout, anchor, state->world_from_cam,
                                             state->cameras, options.position_weight,
                                             settings.orientation_weight, std::move(ray_times)));
    for (const bool held : lm_problem->held) camera_observed.push_back(!held);
  } else {
    RayTimeProblemSettings problem_settings;
    problem_settings.position_weight = options.position_weight;
    problem_settings.orientation_weight = settings.orientation_weight;
    problem_settings.loss_scale_px2 = settings.scales.front();
    problem_settings.refine_focal = settings.refine_focal;
    problem_settings.refine_principal_point = settings.refine_principal_point;
    problem_settings.refine_distortion = settings.refine_distortion;
    problem_settings.use_evaluation_cache = options.use_evaluation_cache;
    problem_settings.num_threads = options.Threads();
    ceres_problem.emplace(input, layout, anchor, state->world_from_cam, state->cameras, ray_times,
                          problem_settings);
    camera_observed = ceres_problem->camera_observed();
  }
  pass.build_seconds = SecondsSince(build_start);

  pass.num_cameras = static_cast<int>(input.prior_world_from_cam.size());
  pass.num_observations = static_cast<int>(layout.observations.size());
  pass.num_ray_times = static_cast<int>(layout.ray_time_observation.size());
  pass.num_tracks = layout.num_tracks;
  pass.num_matches_input = layout.num_matches_input;
  pass.num_matches_used = layout.num_matches_used;
  pass.num_residuals = static_cast<int>(layout.residuals.size());
  spdlog::info(
      fmt::format("refine: {}: {} cameras, {} of {} matches, {} residuals, {} ray times ({} init, "
                  "median depth {:.3g}), built in {:.2f} s, solver {}",
                  pass.name, pass.num_cameras, pass.num_matches_used, pass.num_matches_input,
                  pass.num_residuals, pass.num_ray_times, pass.ray_time_init.mode,
                  pass.ray_time_init.median_depth, pass.build_seconds, pass.solver));

  const auto solve_start = std::chrono::steady_clock::now();
  if (lm_problem) {
    RayTimeLmSettings solver_settings;
    solver_settings.scales = settings.scales;
    solver_settings.max_iterations = options.max_iterations;
    solver_settings.function_tolerance = options.function_tolerance;
    solver_settings.num_threads = options.Threads();
    pass.stages = SolveGncRayTimeLm(&*lm_problem, solver_settings);
    // The eliminated group is every ray time (§3.4), by construction.
    pass.elimination_group_size = pass.num_ray_times;
    state->world_from_cam = lm_problem->world_from_cam;
    solved_ray_times = std::move(lm_problem->ray_times);
    lm_problem.reset();
  } else {
    GncSolverSettings solver_settings;
    solver_settings.scales = settings.scales;
    solver_settings.max_iterations = options.max_iterations;
    solver_settings.function_tolerance = options.function_tolerance;
    solver_settings.num_threads = options.deterministic ? 1 : options.Threads();
    pass.stages = SolveGnc(&*ceres_problem, solver_settings, &pass.elimination_group_size);
    state->world_from_cam = ceres_problem->WorldFromCam();
    state->cameras.cameras = ceres_problem->Intrinsics();
    solved_ray_times = ceres_problem->ray_times();
    ceres_problem.reset();
  }
  pass.solve_seconds = SecondsSince(solve_start);
  pass.gauge_polish =
      PolishGauge(anchor, camera_observed, options.position_weight, settings.orientation_weight,
                  options.gauge_orientation_weight, &state->world_from_cam, &solved_ray_times);
  for (size_t t = 0; t < solved_ray_times.size(); ++t) {
    state->ray_time_by_observation[KeyOf(layout.observations[layout.ray_time_observation[t]])] =
        solved_ray_times[t];
  }
  // The polish moves cameras and ray times by one similarity: the residuals are the solve's.
  std::vector<double> norms =
      ResidualNorms(input, layout, state->world_from_cam, state->cameras, solved_ray_times);
  double loss_sum = 0.0;
  for (const double norm : norms) {
    loss_sum += options.loss_scale_px2 * std::atan(norm * norm / options.loss_scale_px2);
  }
  pass.match_cost_px2 = norms.empty() ? 0.0 : loss_sum / static_cast<double>(norms.size());
  pass.residual_median_px = Median(norms, 0.0);
  if (!norms.empty()) {
    const size_t rank = (norms.size() * 9 + 9) / 10 - 1;  // nearest rank: ceil(0.9 n) - 1
    std::nth_element(norms.begin(), norms.begin() + rank, norms.end());
    pass.residual_p90_px = norms[rank];
  }
  spdlog::info(fmt::format(
      "refine: {}: residuals at the solution: median {:.3g} px, 90th percentile {:.3g} px, mean "
      "match term {:.4g} px²",
      pass.name, pass.residual_median_px, pass.residual_p90_px, pass.match_cost_px2));
  return pass;
}

// The last pass's observations, their solved ray times and its used matches (RefineOutput).
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

// Per image pair with matches in `layout`, its median positive-ray epipolar distance at the given
// poses and intrinsics blocks (PairResidualMedians' plain arrays from the layout; input order).
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

// The same at the last pass's solved poses and intrinsics, on its used matches.
std::vector<PairResidual> SolvedPairResiduals(const RefineInput& input, const PassState& state) {
  return PairResidualsAt(input, state.layout, state.world_from_cam, state.cameras);
}

// The blocks of the last pass's layout and the fewest observations one of them has.
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

// The match graph's edges: (image1, image2) of every pair with matches, in input order.
std::vector<std::pair<int, int>> MatchedEdges(const RefineInput& input) {
  std::vector<std::pair<int, int>> edges;
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.matches.rows() > 0) edges.emplace_back(pair.image1, pair.image2);
  }
  return edges;
}

int CountComponents(int num_images, const std::vector<std::pair<int, int>>& edges) {
  const std::vector<int> labels = ConnectedComponents(num_images, edges);
  return labels.empty() ? 0 : *std::max_element(labels.begin(), labels.end()) + 1;
}

// The pairs of `input` that `residuals` (of every pair, any order) put above threshold_px,
// worst first, except one whose removal would split the match graph further (appended to
// *kept): the pairs to leave out of the next solve.
std::vector<PairResidual> SelectInconsistentPairs(std::vector<PairResidual> residuals,
                                                  double threshold_px, const RefineInput& input,
                                                  std::vector<PairResidual>* kept) {
  std::stable_sort(
      residuals.begin(), residuals.end(),
      [](const PairResidual& a, const PairResidual& b) { return a.median_px > b.median_px; });
  const int num_images = static_cast<int>(input.prior_world_from_cam.size());
  std::vector<std::pair<int, int>> edges = MatchedEdges(input);
  const int components = CountComponents(num_images, edges);
  std::vector<PairResidual> selected;
  for (const PairResidual& residual : residuals) {
    if (!(residual.median_px > threshold_px)) break;  // sorted; infinite, never NaN
    const auto it =
        std::find(edges.begin(), edges.end(), std::make_pair(residual.image1, residual.image2));
    if (it == edges.end()) continue;
    const auto index = it - edges.begin();
    edges.erase(it);
    if (CountComponents(num_images, edges) > components) {
      edges.insert(edges.begin() + index, {residual.image1, residual.image2});
      kept->push_back(residual);
      continue;
    }
    selected.push_back(residual);
  }
  return selected;
}

// The (image1, image2) keys of `pairs`.
std::set<std::pair<int, int>> PairKeys(const std::vector<PairResidual>& pairs) {
  std::set<std::pair<int, int>> keys;
  for (const PairResidual& pair : pairs) keys.emplace(pair.image1, pair.image2);
  return keys;
}

// `input` without the pairs of `removed` (every other field as it is).
RefineInput WithoutPairs(const RefineInput& input, const std::vector<PairResidual>& removed) {
  const std::set<std::pair<int, int>> drop = PairKeys(removed);
  RefineInput out = input;
  out.pairs.erase(std::remove_if(out.pairs.begin(), out.pairs.end(),
                                 [&](const PairMatchIndices& pair) {
                                   return drop.count({pair.image1, pair.image2}) > 0;
                                 }),
                  out.pairs.end());
  return out;
}

bool SamePairs(const std::vector<PairResidual>& a, const std::vector<PairResidual>& b) {
  return PairKeys(a) == PairKeys(b);
}

// The finish anneal's arctan scale (RefineOptions::finish_noise_multiple): (k m)², m the basin's
// median residual, at least kMinFinishAnnealScalePx2; 0 when that is not below loss_scale_px2 (no
// anneal).
double FinishAnnealScale(const RefineOptions& options, double basin_median_px) {
  // SIFT keypoints are located to about half a pixel: a median below that says the basin fitted
  // few matches closely (or the data is noise-free), not that matches half a pixel off are wrong.
  // Without this floor, a noise-free synthetic scene's median of 1e-5 px gave a scale of 1e-10
  // px², where every residual is in the loss's flat tail and the solve drifted 0.8°.
  constexpr double kMinFinishAnnealScalePx2 = 0.25;
  const double target = std::max(std::pow(options.finish_noise_multiple * basin_median_px, 2),
                                 kMinFinishAnnealScalePx2);
  return options.finish_noise_multiple > 0 && target < options.loss_scale_px2 ? target : 0.0;
}

// refine/loose_parts.h's verdict on the input's match graph. A pair the removal took counts as
// removed only while the returned solution leaves it unexplained (above threshold_px, on the
// basin's capped matches): a removal made at a pulled-off basin solution whose pairs the finish
// explains again took nothing that held a part (an oscillating removal took 13 of a correct desk
// frame's 18 pairs so).
LoosePartsVerdict CheckLooseParts(const RefineInput& input, const PairRemovalSummary& removal,
                                  const PassState& state, const RefineOptions& options,
                                  double threshold_px) {
  std::set<std::pair<int, int>> unexplained;
  if (!removal.removed.empty()) {
    const std::set<std::pair<int, int>> removed = PairKeys(removal.removed);
    RefineInput removed_only = input;
    removed_only.pairs.clear();
    for (const PairMatchIndices& pair : input.pairs) {
      if (removed.count({pair.image1, pair.image2})) removed_only.pairs.push_back(pair);
    }
    const ProblemLayout layout = BuildPerObservationLayout(
        removed_only, options.basin_max_matches_per_pair, options.match_cap_seed);
    for (const PairResidual& pair :
         PairResidualsAt(removed_only, layout, state.world_from_cam, state.cameras)) {
      if (!(pair.median_px <= threshold_px)) unexplained.emplace(pair.image1, pair.image2);
    }
  }
  std::vector<GraphPair> graph;
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.matches.rows() == 0) continue;
    graph.push_back({pair.image1, pair.image2, static_cast<int>(pair.matches.rows()),
                     unexplained.count({pair.image1, pair.image2}) > 0});
  }
  LoosePartsVerdict verdict;
  verdict.cuts = FindLooseCuts(static_cast<int>(input.prior_world_from_cam.size()), graph);
  std::set<int> images;
  for (const LooseCut& cut : verdict.cuts) images.insert(cut.images.begin(), cut.images.end());
  verdict.images.assign(images.begin(), images.end());
  return verdict;
}

// The basin-first solve (RefineOptions::basin_first): basin pass, wrong-pair removal with basin
// solves again (when enabled), orientation-prior probe, finish. When pairs are removed, *pruned
// holds the input without them, which the later passes and the posterior checks use.
void RunBasinFirst(const RefineInput& input, const RefineOptions& options,
                   const PassSettings& nominal, const std::vector<Rigid3>& prior, PassState* state,
                   RefineSummary* summary, std::optional<RefineInput>* pruned) {
  PassSettings basin;
  basin.name = "basin";
  basin.max_matches_per_pair = options.basin_max_matches_per_pair;
  basin.orientation_weight = 0.0;
  basin.scales = options.StageScales();
  const PassState start = *state;
  summary->passes.push_back(RunPass(input, options, basin, prior, state));

  // Wrong-pair removal: every pair of the input is judged at the current basin solution (on the
  // basin's capped matches), and the basin is solved again from the prior without the ones above
  // the threshold, until the solution leaves exactly the pairs it was solved without (or none)
  // above it. Judging the removed pairs again matters: a solution pulled off by wrong pairs leaves
  // some correct ones off too, and they come back once it is right. Solving from the prior again
  // (not from the pulled-off solution) gives the GNC schedule its whole basin.
  const RefineInput* active = &input;
  PairRemovalSummary& removal = summary->pair_removal;
  removal.enabled = options.max_pair_removal_rounds > 0;
  if (removal.enabled) {
    const ProblemLayout judged = BuildPerObservationLayout(
        input, options.basin_max_matches_per_pair, options.match_cap_seed);
    while (true) {
      const std::vector<PairResidual> residuals =
          PairResidualsAt(input, judged, state->world_from_cam, state->cameras);
      std::vector<PairResidual> kept;
      const std::vector<PairResidual> selected =
          SelectInconsistentPairs(residuals, options.inconsistent_pair_px, input, &kept);
      if (selected.empty() && kept.empty() && removal.removed.empty()) {
        removal.stop_reason = "consistent";
        break;
      }
      if (SamePairs(selected, removal.removed)) {
        // Nothing removable but bridges above the threshold: they are still reported.
        if (removal.rounds == 0) removal.kept = kept;
        removal.stop_reason = selected.empty() && removal.kept.empty() ? "consistent" : "stable";
        break;
      }
      if (removal.rounds == options.max_pair_removal_rounds) {
        removal.stop_reason = "max_rounds";
        break;
      }
      ++removal.rounds;
      removal.removed = selected;
      removal.kept = kept;
      pruned->emplace(WithoutPairs(input, selected));
      active = &pruned->value();
      spdlog::info(fmt::format(
          "refine: {} of {} pairs above {:.3g} px at the basin solution{}{}; solving the basin "
          "again from the prior without them (round {} of at most {})",
          selected.size(), residuals.size(), options.inconsistent_pair_px,
          selected.empty() ? std::string()
                           : fmt::format(" (worst ({}, {}) {:.1f} px)", selected.front().image1,
                                         selected.front().image2, selected.front().median_px),
          kept.empty() ? std::string()
                       : fmt::format(", {} kept to hold the graph together", kept.size()),
          removal.rounds, options.max_pair_removal_rounds));
      *state = start;
      PassSettings again = basin;
      again.name = "basin_round" + std::to_string(removal.rounds + 1);
      summary->passes.push_back(RunPass(*active, options, again, prior, state));
    }
  }
  const PassState basin_state = *state;

  OrientationPriorProbe& probe = summary->orientation_prior;
  probe.enabled = true;
  probe.weight = options.orientation_weight;
  probe.max_increase = options.orientation_prior_max_increase;
  probe.free_residual_median_px = summary->passes.back().residual_median_px;
  probe.free_match_cost_px2 = summary->passes.back().match_cost_px2;
  probe.prior_from_matches = input.prior_rotations_from_matches && options.orientation_weight > 0;
  if (probe.prior_from_matches) {
    spdlog::info(fmt::format(
        "refine: orientation prior (λR = {:g}) not used: the prior's rotations were estimated "
        "from these matches (the bootstrap or a repair from it), so they add nothing but their "
        "own errors; the finish runs with λR = 0",
        probe.weight));
  } else if (options.orientation_weight > 0) {
    PassSettings probe_pass = basin;
    probe_pass.name = "orientation_probe";
    probe_pass.orientation_weight = options.orientation_weight;
    probe_pass.scales = {options.loss_scale_px2};
    summary->passes.push_back(RunPass(*active, options, probe_pass, prior, state));
    probe.prior_residual_median_px = summary->passes.back().residual_median_px;
    probe.prior_match_cost_px2 = summary->passes.back().match_cost_px2;
    probe.increase = probe.free_residual_median_px > 0
                         ? probe.prior_residual_median_px / probe.free_residual_median_px - 1.0
                         : 0.0;
    for (size_t i = 0; i < prior.size(); ++i) {
      probe.max_rotation_change_deg = std::max(
          probe.max_rotation_change_deg, RotationDistance(basin_state.world_from_cam[i].rotation,
                                                          state->world_from_cam[i].rotation) *
                                             180.0 / M_PI);
    }
    probe.kept = probe.increase <= probe.max_increase;
    if (probe.kept) {
      spdlog::info(fmt::format(
          "refine: orientation prior (λR = {:g}) kept: the matches agree with the prior's "
          "rotations (median residual {:+.2f} % under it, threshold {:+.2f} %; rotations moved "
          "up to {:.3f}°)",
          probe.weight, 100 * probe.increase, 100 * probe.max_increase,
          probe.max_rotation_change_deg));
    } else {
      spdlog::info(fmt::format(
          "refine: orientation prior (λR = {:g}) dropped: the matches contradict the prior's "
          "rotations (median residual {:+.2f} % under it, threshold {:+.2f} %; it moved rotations "
          "up to {:.3f}°); the finish runs with λR = 0 from the basin solve",
          probe.weight, 100 * probe.increase, 100 * probe.max_increase,
          probe.max_rotation_change_deg));
      *state = basin_state;
    }
  }

  PassSettings finish = nominal;
  finish.name = "finish";
  finish.scales = {options.loss_scale_px2};
  finish.orientation_weight = probe.kept ? options.orientation_weight : 0.0;
  finish.start_unsolved_at_closest_approach = true;
  summary->passes.push_back(RunPass(*active, options, finish, prior, state));
  // The finish anneal (RefineOptions::finish_noise_multiple) keeps the finish's orientation prior
  // but not its anchor: after a λR = 0 finish none; after a finish that kept λR, the same λR
  // towards the finish's own rotations. Towards the prior's (λR as it is), a prior the probe kept
  // but that is slightly wrong (a 1° ladder prior: +4.8 % median residual, just under the
  // threshold) took the rotations back as the shrinking scale weakened the matches' pull: 1.0-2.2°
  // on 4 of 24 ladder runs at 1-2°, one of them unflagged. With no prior at all, the long Record3D
  // desk sweep drifted 0.196° (median relative rotation) from the finish, unflagged: the mode of
  // docs/real_captures.md that made the probe keep λR there; held at the finish it moved 0.012°.
  // At the finish's full λR the hold costs castle-P19 from an exact prior (0.122° against 0.039°
  // without it); RefineOptions::finish_anneal_hold_ratio weakens it (0.01 in auto). One stage,
  // straight to its scale: through the decade between, as GNC would, the same errors to 0.001° on
  // the four Strecha scenes at 0° and 8°, with 35 % more iterations.
  const double anneal_scale = FinishAnnealScale(options, probe.free_residual_median_px);
  if (anneal_scale > 0) {
    PassSettings anneal = finish;
    anneal.name = "finish_anneal";
    anneal.scales = {anneal_scale};
    anneal.orientation_weight = finish.orientation_weight * options.finish_anneal_hold_ratio;
    // Only the rotations: the centres' terms and the gauge stay the prior's, as in every pass.
    std::vector<Rigid3> anchor = prior;
    for (size_t i = 0; i < anchor.size(); ++i) {
      anchor[i].rotation = state->world_from_cam[i].rotation;
    }
    spdlog::info(fmt::format(
        "refine: the finish anneals on to {:.3g} px² ({:g} x the basin's median residual {:.3f} "
        "px, squared), {}",
        anneal_scale, options.finish_noise_multiple, probe.free_residual_median_px,
        anneal.orientation_weight > 0
            ? fmt::format("λR = {:g} towards the finish's rotations", anneal.orientation_weight)
            : std::string("λR = 0")));
    summary->passes.push_back(RunPass(*active, options, anneal, anchor, state));
  }
}

}  // namespace

RefineSummary RefinePoses(const RefineInput& input, const RefineOptions& options,
                          RefineOutput* output) {
  const auto start = std::chrono::steady_clock::now();
  ValidateOptions(options, "refine");
  ValidateInput(input);
  RefineSummary summary;

  std::vector<Rigid3> prior = input.prior_world_from_cam;
  for (Rigid3& pose : prior) pose.rotation.normalize();
  PassState state;
  state.world_from_cam = prior;
  // The intrinsics blocks (refine/camera_blocks.h): one shared set only when self-calibrating
  // one, else the images' own cameras. Every pass of the run uses the same blocks.
  summary.cameras.sharing = options.intrinsics_sharing;
  std::vector<bool> camera_in_use(input.cameras.size(), false);
  for (const int camera : input.camera_index) camera_in_use[camera] = true;
  summary.cameras.num_cameras =
      static_cast<int>(std::count(camera_in_use.begin(), camera_in_use.end(), true));
  if (options.intrinsics_sharing == "shared") {  // self-calibrating (RefineOptions relations)
    state.cameras = SharedBlock(input, &summary.cameras.max_start_disagreement_px);
    summary.cameras.cameras_differ =
        summary.cameras.max_start_disagreement_px > kSharedCameraTolerancePx;
    if (summary.cameras.cameras_differ) {
      spdlog::warn(fmt::format(
          "refine: {} cameras differ by up to {:.3g} px on the image from the shared intrinsics "
          "started at their median (intrinsics_sharing: shared); their per-image values are "
          "replaced by one refined set",
          summary.cameras.num_cameras, summary.cameras.max_start_disagreement_px));
    }
  } else {
    state.cameras = PerCameraBlocks(input);
  }

  std::optional<RefineInput> pruned;  // the input less the pairs the basin-first solve removed
  PassSettings nominal;
  nominal.name = "solve";
  nominal.max_matches_per_pair = options.max_matches_per_pair;
  nominal.orientation_weight = options.orientation_weight;
  nominal.scales = options.StageScales();
  nominal.refine_focal = options.refine_focal;
  nominal.refine_principal_point = options.refine_principal_point;
  nominal.refine_distortion = options.refine_distortion;
  if (options.staged) {
    // §4.3: pass 1 poses only, light orientation anchor, capped matches, full GNC schedule ...
    PassSettings pass1;
    pass1.name = "pass1_poses";
    pass1.max_matches_per_pair = options.stage1_max_matches_per_pair;
    pass1.orientation_weight = options.stage1_orientation_weight;
    pass1.scales = options.StageScales();
    summary.passes.push_back(RunPass(input, options, pass1, prior, &state));
    // ... pass 2 one warm solve at the nominal scale, priors re-anchored at the pass-1 poses.
    PassSettings pass2 = nominal;
    pass2.name = "pass2_self_calibration";
    pass2.scales = {options.loss_scale_px2};
    const std::vector<Rigid3> pass1_poses = state.world_from_cam;
    summary.passes.push_back(RunPass(input, options, pass2, pass1_poses, &state));
  } else if (options.basin_first) {
    RunBasinFirst(input, options, nominal, prior, &state, &summary, &pruned);
  } else {
    summary.passes.push_back(RunPass(input, options, nominal, prior, &state));
  }

  for (const RefinePassSummary& pass : summary.passes) {
    summary.build_seconds += pass.build_seconds;
    summary.solve_seconds += pass.solve_seconds;
    for (const GncStageSummary& stage : pass.stages) {
      summary.total_iterations += stage.iterations;
      summary.jacobian_seconds += stage.jacobian_seconds;
      summary.solver_failed = summary.solver_failed || stage.termination == "FAILURE";
    }
  }
  CountBlocks(state, &summary.cameras);
  spdlog::info(fmt::format(
      "refine: {} camera(s), {} intrinsics block(s) ({}{}), fewest observations on one: "
      "{}",
      summary.cameras.num_cameras, summary.cameras.num_blocks,
      options.SelfCalibrates() ? "self-calibrated, " : "fixed",
      options.SelfCalibrates() ? options.intrinsics_sharing : "",
      summary.cameras.min_block_observations));
  summary.initial_cost = summary.passes.front().stages.front().initial_cost;
  const RefinePassSummary& last = summary.passes.back();
  summary.final_cost = last.stages.back().final_cost -
                       (last.gauge_polish.prior_cost_before - last.gauge_polish.prior_cost_after);

  // Posterior guardrails against the original prior.
  if (summary.solver_failed) summary.guardrails_fired.push_back("solver_failure");
  if (options.trust_region) {
    summary.trust_region =
        CheckTrustRegion(prior, state.world_from_cam, options.trust_region_rotation_deg,
                         options.trust_region_translation_m * options.length_unit_m);
    if (summary.trust_region.fired) summary.guardrails_fired.push_back("trust_region");
  }
  if (options.wander_test) {
    summary.wander =
        CheckWander(prior, state.world_from_cam, options.wander_expected_m * options.length_unit_m,
                    options.wander_factor);
    if (summary.wander.fired) summary.guardrails_fired.push_back("wander");
  }
  summary.returned_prior = !summary.guardrails_fired.empty();
  // Against the solve's own matches (prior-independent), flag only.
  if (options.inconsistent_pairs_test) {
    summary.inconsistent_pairs = CheckInconsistentPairs(
        SolvedPairResiduals(pruned ? *pruned : input, state), options.inconsistent_pair_px,
        options.inconsistent_pair_median_multiple, options.max_inconsistent_pair_fraction);
    if (summary.inconsistent_pairs.fired) summary.guardrails_fired.push_back("inconsistent_pairs");
  }
  // A part resting on a pair or two nothing else checks looks consistent whether they are right or
  // not (its poses simply follow them), as does one whose disagreeing pairs the removal took.
  summary.loose_parts =
      CheckLooseParts(input, summary.pair_removal, state, options,
                      options.inconsistent_pairs_test ? summary.inconsistent_pairs.pair_threshold_px
                                                      : options.inconsistent_pair_px);
  if (!summary.loose_parts.images.empty()) summary.guardrails_fired.push_back("loose_parts");

  output->solved_world_from_cam = state.world_from_cam;
  output->solved_cameras = InputCameras(input, state.cameras);
  output->solved_observations = SolvedObservationsOf(state);
  output->world_from_cam = summary.returned_prior ? prior : state.world_from_cam;
  output->cameras = summary.returned_prior ? input.cameras : output->solved_cameras;
  summary.total_seconds = SecondsSince(start);
  if (summary.trust_region.enabled) {
    spdlog::info(fmt::format(
        "refine: trust region: moved at most {:.3f}° / {:.4g} (thresholds {:.3g}° / "
        "{:.4g}){}",
        summary.trust_region.max_rotation_deg, summary.trust_region.max_translation,
        summary.trust_region.rotation_threshold_deg, summary.trust_region.translation_threshold,
        summary.trust_region.fired ? ": FIRED" : ""));
  }
  if (summary.wander.enabled) {
    spdlog::info(
        fmt::format("refine: wander test: median Sim(3)-aligned displacement {:.4g} (threshold "
                    "{:.4g}){}",
                    summary.wander.median_displacement, summary.wander.threshold,
                    summary.wander.fired ? ": FIRED" : ""));
  }
  const InconsistentPairsVerdict& pairs = summary.inconsistent_pairs;
  if (pairs.enabled) {
    spdlog::info(fmt::format(
        "refine: inconsistent pairs: {} of {} pairs above {:.3g} px (median pair {:.3g} px), "
        "fraction {:.3f} (threshold {:.3g}){}",
        pairs.num_inconsistent, pairs.num_pairs, pairs.pair_threshold_px, pairs.median_pair_px,
        pairs.fraction, pairs.fraction_threshold, pairs.fired ? ": FIRED" : ""));
  }
  const PairRemovalSummary& removal = summary.pair_removal;
  if (summary.returned_prior) {
    summary.decision = "returned_prior";
  } else if (!summary.guardrails_fired.empty()) {
    summary.decision = "flagged";
  } else if (!removal.removed.empty()) {
    summary.decision = "re_solved";
  } else {
    summary.decision = "accepted";
  }
  if (summary.returned_prior) {
    spdlog::warn(fmt::format("refine: guardrail fired ({}): returning the prior",
                             summary.guardrails_fired.front()));
  }
  if (removal.enabled) {
    spdlog::info(
        fmt::format("refine: pair removal: {} pair(s) removed in {} round(s), stopped: {}{}",
                    removal.removed.size(), removal.rounds, removal.stop_reason,
                    removal.kept.empty()
                        ? std::string()
                        : fmt::format(" ({} inconsistent pair(s) kept to hold the graph together)",
                                      removal.kept.size())));
  }
  for (const LooseCut& cut : summary.loose_parts.cuts) {
    // A part inside a larger loose one is in the summary, not in the log.
    const auto holds = [&](const LooseCut& other) {
      return other.images.size() > cut.images.size() &&
             std::includes(other.images.begin(), other.images.end(), cut.images.begin(),
                           cut.images.end());
    };
    const auto& cuts = summary.loose_parts.cuts;
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
  if (pairs.fired) {
    // The first few in the log; all of them in the summary.
    constexpr size_t kLogged = 8;
    std::string listed;
    for (size_t p = 0; p < std::min(kLogged, pairs.pairs.size()); ++p) {
      listed += fmt::format("{}({}, {}) {:.1f} px", p == 0 ? "" : ", ",
                            input.Label(pairs.pairs[p].image1), input.Label(pairs.pairs[p].image2),
                            pairs.pairs[p].median_px);
    }
    if (pairs.pairs.size() > kLogged) listed += ", ...";
    spdlog::warn(fmt::format(
        "refine: guardrail fired (inconsistent_pairs): the solution leaves {} of {} image pairs' "
        "matches unexplained (wrong pairs, e.g. repeated structure, may have pulled it off): {}{}",
        pairs.num_inconsistent, pairs.num_pairs, listed,
        pairs.images_mostly_inconsistent.empty()
            ? std::string()
            : fmt::format(
                  "; most pairs of image(s) {} are among them: their poses are likely wrong",
                  fmt::join(Labels(input, pairs.images_mostly_inconsistent), ", "))));
  }
  return summary;
}

nlohmann::json RefineSummary::ToJson() const {
  return {{"passes", passes},
          {"cameras", cameras},
          {"total_iterations", total_iterations},
          {"initial_cost", initial_cost},
          {"final_cost", final_cost},
          {"timings",
           {{"build_seconds", build_seconds},
            {"solve_seconds", solve_seconds},
            {"jacobian_seconds", jacobian_seconds},
            {"total_seconds", total_seconds}}},
          {"orientation_prior", orientation_prior},
          {"pair_removal", pair_removal},
          {"decision", decision},
          {"guardrails",
           {{"fired", guardrails_fired},
            {"returned_prior", returned_prior},
            {"solver_failed", solver_failed},
            {"trust_region", trust_region},
            {"wander", wander},
            {"inconsistent_pairs", inconsistent_pairs},
            {"loose_parts", loose_parts}}}};
}

}  // namespace raytime
