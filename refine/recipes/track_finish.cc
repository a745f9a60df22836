#include "refine/recipes/track_finish.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <utility>

#include "core/graph.h"
#include "core/statistics.h"
#include "core/timing.h"
#include "refine/solve/gauge_polish.h"
#include "refine/solve/problem_layout.h"
#include "refine/solve/ray_geometry.h"
#include "refine/solve/track_adjustment.h"

namespace raytime {
namespace {

using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

// Each layout observation's ray point X = O + t·R·d at the state (NaN without a ray time).
std::vector<Eigen::Vector3d> RayPoints(const PassState& state, const ObservationRays& rays) {
  const ProblemLayout& layout = state.layout;
  std::vector<Eigen::Vector3d> points(layout.observations.size(),
                                      Eigen::Vector3d::Constant(std::nan("")));
  for (size_t o = 0; o < layout.observations.size(); ++o) {
    const LayoutObservation& obs = layout.observations[o];
    if (obs.ray_time < 0) continue;
    const Rigid3& pose = state.world_from_cam[obs.image];
    const double t = state.ray_time_by_observation.at(WarmRayTimeKey(obs.image, obs.keypoint));
    points[o] = pose.translation + t * (pose.rotation * rays.rays[o]);
  }
  return points;
}

// |π_image(X) − û|², infinite behind the camera.
double SquaredResidual(const PassState& state, int image, const Eigen::Vector3d& X,
                       const Eigen::Vector2d& undistorted) {
  const Rigid3& pose = state.world_from_cam[image];
  const RowMajor3 R = pose.rotation.normalized().toRotationMatrix();
  double offset[3], p_cam[3], residual[2];
  TargetResidual(R.data(), pose.translation.data(), state.cameras.Of(image).params.data(), X.data(),
                 undistorted.data(), offset, p_cam, residual);
  if (!(p_cam[2] > 0.0)) return std::numeric_limits<double>::infinity();
  return residual[0] * residual[0] + residual[1] * residual[1];
}

// 1-2. The inlier matches' union-find components, one observation per image; per track its
// layout observations.
std::vector<std::vector<int>> InlierTracks(const PassState& state, const ObservationRays& rays,
                                           const std::vector<Eigen::Vector3d>& ray_points,
                                           double threshold_px2, TrackFinishSummary* summary) {
  const ProblemLayout& layout = state.layout;
  const int num_observations = static_cast<int>(layout.observations.size());
  UnionFind sets(num_observations);
  for (const LayoutMatch& match : layout.matches) {
    const int o1 = match.observation1, o2 = match.observation2;
    const int image1 = layout.observations[o1].image, image2 = layout.observations[o2].image;
    if (!ray_points[o1].allFinite() || !ray_points[o2].allFinite()) continue;
    if (SquaredResidual(state, image2, ray_points[o1], rays.undistorted[o2]) > threshold_px2 ||
        SquaredResidual(state, image1, ray_points[o2], rays.undistorted[o1]) > threshold_px2) {
      continue;
    }
    ++summary->num_inliers;
    sets.Union(o1, o2);
  }
  std::map<int, std::vector<int>> by_root;
  for (int o = 0; o < num_observations; ++o) by_root[sets.Find(o)].push_back(o);
  std::vector<std::vector<int>> tracks;
  for (auto& [root, observations] : by_root) {
    if (observations.size() < 2) continue;
    std::vector<int> images;
    for (const int o : observations) images.push_back(layout.observations[o].image);
    std::sort(images.begin(), images.end());
    if (std::adjacent_find(images.begin(), images.end()) != images.end()) {
      ++summary->num_conflicting;
      continue;
    }
    tracks.push_back(std::move(observations));
  }
  return tracks;
}

// 3. The adjustment's problem: every track's point the mean of its observations' ray points, a
// track whose point one of its cameras sees behind it left out.
TrackAdjustmentProblem BuildProblem(const RefineOptions& options, const RefinePassSummary& last,
                                    const PassState& state, const ObservationRays& rays,
                                    const std::vector<Eigen::Vector3d>& ray_points,
                                    const std::vector<std::vector<int>>& tracks,
                                    std::vector<std::vector<int>>* kept) {
  const ProblemLayout& layout = state.layout;
  TrackAdjustmentProblem problem;
  problem.world_from_cam = state.world_from_cam;
  problem.anchor = state.anchor;
  for (size_t i = 0; i < state.world_from_cam.size(); ++i) {
    const auto& p = state.cameras.Of(static_cast<int>(i)).params;
    problem.pinhole.emplace_back(p[kFx], p[kFy], p[kCx], p[kCy]);
  }
  problem.position_weight = options.position_weight;
  problem.orientation_weight = last.orientation_weight;
  for (const std::vector<int>& track : tracks) {
    Eigen::Vector3d X = Eigen::Vector3d::Zero();
    for (const int o : track) X += ray_points[o];
    X /= static_cast<double>(track.size());
    const bool in_front = std::all_of(track.begin(), track.end(), [&](int o) {
      return std::isfinite(
          SquaredResidual(state, layout.observations[o].image, X, rays.undistorted[o]));
    });
    if (!in_front) continue;
    const int k = static_cast<int>(problem.points.size());
    problem.points.push_back(X);
    for (const int o : track) {
      problem.observation_track.push_back(k);
      problem.observation_image.push_back(layout.observations[o].image);
      problem.observation_pixel.push_back(rays.undistorted[o]);
    }
    kept->push_back(track);
  }
  return problem;
}

// 6. The check against the ray-time solution (`before`, its σ in `ray_time`); an empty string
// when the finish stands, else why not.
std::string CheckFinish(const RefineOptions& options, const TrackAdjustmentSummary& adjustment,
                        const std::vector<Rigid3>& before, const std::vector<Rigid3>& after,
                        const PoseUncertaintySummary& ray_time,
                        const PoseUncertaintySummary& adjusted, TrackFinishSummary* summary) {
  std::vector<double> moves;
  for (size_t i = 0; i < before.size(); ++i) {
    const PoseUncertainty& sigma = ray_time.cameras[i];
    if (!(sigma.rotation_deg > 0.0) || !(sigma.centre > 0.0)) continue;
    const double rotation =
        DegreesFromRadians(RotationDistance(before[i].rotation, after[i].rotation));
    const double centre = (before[i].translation - after[i].translation).norm();
    summary->max_rotation_move_deg = std::max(summary->max_rotation_move_deg, rotation);
    summary->max_centre_move = std::max(summary->max_centre_move, centre);
    moves.push_back(std::max(rotation / sigma.rotation_deg, centre / sigma.centre));
    if (!(moves.back() <= summary->max_move_sigma)) {
      summary->max_move_sigma = moves.back();
      summary->max_move_image = static_cast<int>(i);
    }
  }
  summary->median_move_sigma = Median(moves, 0.0);
  if (!adjustment.converged) return "the adjustment did not converge: " + adjustment.message;
  if (!adjusted.computed) return "no uncertainty at its solution: " + adjusted.reason;
  if (!(summary->adjusted_sigma_px <= kTrackFinishMaxNoiseRatio * summary->ray_time_sigma_px)) {
    return fmt::format(
        "its residuals imply {:.3g} px keypoint noise, the ray-time solve's {:.3g} px (at most "
        "{:g}x): tracks the noise does not explain",
        summary->adjusted_sigma_px, summary->ray_time_sigma_px, kTrackFinishMaxNoiseRatio);
  }
  const double allowed =
      options.track_finish_max_move_sigma * std::max(1.0, summary->median_move_sigma);
  if (!(summary->max_move_sigma <= allowed)) {
    return fmt::format(
        "it moved frame {} by {:.3g} σ of its ray-time pose, the median frame {:.3g} σ (at most "
        "{:g} x the median frame's, at least 1 σ)",
        summary->max_move_image, summary->max_move_sigma, summary->median_move_sigma,
        options.track_finish_max_move_sigma);
  }
  return "";
}

// Gauss–Newton steps per point before the rejection round: from the mean of its ray points, each
// point's residuals are those of the adjustment's solution but for the poses' part.
constexpr int kPointIterations = 3;

// 4. The rejection round: the observations the points leave above kRejectSigmas of the noise
// their residuals imply (their median, as a 2D Gaussian's: 1.1774 σ) leave it, and a track
// left with one observation goes. Returns how many observations went.
int RejectObservations(TrackAdjustmentProblem* problem, std::vector<std::vector<int>>* tracks) {
  constexpr double kRejectSigmas = 4.0;  // a Gaussian residual beyond it: 1 in 3000
  const int n = static_cast<int>(problem->observation_track.size());
  std::vector<double> norms(n);
  for (int o = 0; o < n; ++o) norms[o] = TrackResidual(*problem, o).norm();
  std::vector<double> sorted = norms;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const double limit = kRejectSigmas * sorted[n / 2] / std::sqrt(2.0 * std::log(2.0));
  TrackAdjustmentProblem kept = *problem;
  kept.points.clear();
  kept.observation_track.clear();
  kept.observation_image.clear();
  kept.observation_pixel.clear();
  std::vector<std::vector<int>> kept_tracks;
  int rejected = 0;
  for (int o = 0; o < n;) {
    const int k = problem->observation_track[o];
    std::vector<int> inside;
    std::vector<int> layout_observations;
    for (size_t j = 0; o < n && problem->observation_track[o] == k; ++o, ++j) {
      if (norms[o] <= limit) {
        inside.push_back(o);
        layout_observations.push_back((*tracks)[k][j]);
      }
    }
    rejected += static_cast<int>((*tracks)[k].size() - inside.size());
    if (inside.size() < 2) continue;
    for (const int i : inside) {
      kept.observation_track.push_back(static_cast<int>(kept.points.size()));
      kept.observation_image.push_back(problem->observation_image[i]);
      kept.observation_pixel.push_back(problem->observation_pixel[i]);
    }
    kept.points.push_back(problem->points[k]);
    kept_tracks.push_back(std::move(layout_observations));
  }
  *problem = std::move(kept);
  *tracks = std::move(kept_tracks);
  return rejected;
}

// The keypoint noise the tracks' residuals imply at the problem's poses and points: Σ |r|² over
// its degrees of freedom, 2 per observation less 3 per point (the poses held).
double NoiseOfPoints(const TrackAdjustmentProblem& problem) {
  const int n = static_cast<int>(problem.observation_track.size());
  double squares = 0.0;
  for (int o = 0; o < n; ++o) squares += TrackResidual(problem, o).squaredNorm();
  const double freedom = 2.0 * n - 3.0 * static_cast<double>(problem.points.size());
  return freedom > 0.0 ? std::sqrt(squares / freedom) : std::numeric_limits<double>::infinity();
}

// Why the finish does not run on this solve, or an empty string.
std::string NotRunReason(const RefinePassSummary& last, const PoseUncertaintySummary& uncertainty) {
  if (last.self_calibration) return "the last pass self-calibrated (fixed intrinsics only)";
  // Its inliers are judged on every observation's own ray point.
  if (last.num_tracks > 0) return "the anchored parameterization (per_observation only)";
  if (!uncertainty.computed) {
    return "no ray-time uncertainty to check it against (" + uncertainty.reason + ")";
  }
  return "";
}

// Each track observation's ray time (tracks' order): the depth of its track's point along its ray.
std::vector<double> TrackRayTimes(const TrackAdjustmentProblem& problem,
                                  const std::vector<std::vector<int>>& tracks,
                                  const ObservationRays& rays) {
  std::vector<double> ray_times;
  size_t observation = 0;
  for (size_t k = 0; k < tracks.size(); ++k) {
    for (const int o : tracks[k]) {
      const Rigid3& pose = problem.world_from_cam[problem.observation_image[observation++]];
      const double depth = (pose.rotation * rays.rays[o]).dot(problem.points[k] - pose.translation);
      ray_times.push_back(std::max(depth, kRayTimeLowerBound));
    }
  }
  return ray_times;
}

// The state at the adjustment's solution: its poses, and its tracks' observations' ray times.
void TakeSolution(const TrackAdjustmentProblem& problem,
                  const std::vector<std::vector<int>>& tracks, const std::vector<double>& ray_times,
                  PassState* state) {
  state->world_from_cam = problem.world_from_cam;
  size_t t = 0;
  for (const std::vector<int>& track : tracks) {
    for (const int o : track) {
      const LayoutObservation& obs = state->layout.observations[o];
      state->ray_time_by_observation[WarmRayTimeKey(obs.image, obs.keypoint)] = ray_times[t++];
    }
  }
}

}  // namespace

TrackFinishSummary FinishOnTracks(const RefineInput& input, const RefineOptions& options,
                                  const RefinePassSummary& last, PassState* state,
                                  PoseUncertaintySummary* uncertainty) {
  const auto start = std::chrono::steady_clock::now();
  TrackFinishSummary summary;
  summary.enabled = options.track_finish;
  if (!summary.enabled) return summary;
  summary.reason = NotRunReason(last, *uncertainty);
  if (!summary.reason.empty()) {
    spdlog::info("refine: track finish not run: " + summary.reason);
    return summary;
  }
  summary.ran = true;
  summary.ray_time_sigma_px = uncertainty->sigma_px;
  summary.loss_scale_px2 = last.stages.back().loss_scale_px2;
  summary.inlier_threshold_px = std::sqrt(2.0 * summary.loss_scale_px2);
  summary.num_matches = static_cast<int>(state->layout.matches.size());

  // 1-3. Inliers, tracks, points.
  const ObservationRays rays = FixedObservationRays(input, state->layout, state->cameras);
  const std::vector<Eigen::Vector3d> ray_points = RayPoints(*state, rays);
  std::vector<std::vector<int>> tracks;
  TrackAdjustmentProblem problem = BuildProblem(
      options, last, *state, rays, ray_points,
      InlierTracks(*state, rays, ray_points, 2.0 * summary.loss_scale_px2, &summary), &tracks);

  // 4-5. The rejection round on the points adjusted at the ray-time poses, the adjustment and the
  // gauge polish of the last pass.
  AdjustPointsAtFixedPoses(&problem, kPointIterations);
  if (!problem.points.empty()) summary.num_rejected = RejectObservations(&problem, &tracks);
  summary.num_tracks = static_cast<int>(problem.points.size());
  summary.num_observations = static_cast<int>(problem.observation_track.size());
  // The noise test before the adjustment too: the points at the ray-time poses imply a little more
  // noise than the adjustment's solution, and tracks the noise does not explain show already (a
  // long video sweep's adjustment ran tens of iterations to be rejected).
  summary.points_sigma_px = NoiseOfPoints(problem);
  if (!(summary.points_sigma_px <= kTrackFinishMaxNoiseRatio * summary.ray_time_sigma_px)) {
    summary.reason = fmt::format(
        "its tracks imply {:.3g} px keypoint noise at the ray-time poses, the ray-time solve's "
        "{:.3g} px (at most {:g}x): tracks the noise does not explain; not adjusted",
        summary.points_sigma_px, summary.ray_time_sigma_px, kTrackFinishMaxNoiseRatio);
    summary.seconds = SecondsSince(start);
    spdlog::warn(fmt::format(
        "refine: track finish rejected, the ray-time solution stands: {} ({} tracks, {:.2f} s)",
        summary.reason, summary.num_tracks, summary.seconds));
    return summary;
  }
  const TrackAdjustmentSummary adjustment = AdjustTracks(&problem);
  summary.iterations = adjustment.iterations;
  PoseUncertaintySettings settings;
  settings.gauge_position_weight = options.position_weight;
  settings.gauge_orientation_weight = options.gauge_orientation_weight;
  settings.max_cameras = options.uncertainty_max_cameras;
  PoseUncertaintySummary adjusted = EstimateTrackPoseUncertainty(problem, settings);
  summary.adjusted_sigma_px = adjusted.sigma_px;
  std::vector<double> ray_times = TrackRayTimes(problem, tracks, rays);
  std::vector<bool> movable(problem.world_from_cam.size(), false);
  for (const int image : problem.observation_image) movable[image] = true;
  PolishGauge(state->anchor, movable, options.position_weight, last.orientation_weight,
              options.gauge_orientation_weight, &problem.world_from_cam, &ray_times);

  // 6. The check.
  summary.reason = CheckFinish(options, adjustment, state->world_from_cam, problem.world_from_cam,
                               *uncertainty, adjusted, &summary);
  summary.accepted = summary.reason.empty();
  summary.seconds = SecondsSince(start);
  if (!summary.accepted) {
    spdlog::warn(fmt::format(
        "refine: track finish rejected, the ray-time solution stands: {} ({} tracks, {:.2f} s)",
        summary.reason, summary.num_tracks, summary.seconds));
    return summary;
  }
  summary.reason = "accepted";
  TakeSolution(problem, tracks, ray_times, state);
  state->pass_world_from_cam["track_finish"] = state->world_from_cam;
  *uncertainty = adjusted;
  spdlog::info(fmt::format(
      "refine: track finish accepted: {} tracks ({} observations, {} of {} matches within {:.3g} "
      "px, {} observations rejected), keypoint noise {:.3g} px (ray-time {:.3g} px), frames "
      "moved up to {:.3g}° / {:.3g} ({:.2f} σ, the median frame {:.2f} σ), {} iterations, {:.2f} "
      "s",
      summary.num_tracks, summary.num_observations, summary.num_inliers, summary.num_matches,
      summary.inlier_threshold_px, summary.num_rejected, summary.adjusted_sigma_px,
      summary.ray_time_sigma_px, summary.max_rotation_move_deg, summary.max_centre_move,
      summary.max_move_sigma, summary.median_move_sigma, summary.iterations, summary.seconds));
  return summary;
}

}  // namespace raytime
