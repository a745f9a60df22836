#include "refine/solve/ray_time_init.h"

#include <algorithm>
#include <limits>

#include "core/camera.h"
#include "core/statistics.h"

namespace raytime {
namespace {

// Rays that are parallel to within this (1 - cos²) carry no depth information.
constexpr double kMinSinSquared = 1e-10;

// World-frame unit direction of every observation's ray at `world_from_cam`.
std::vector<Eigen::Vector3d> RayDirections(const ProblemLayout& layout, const RefineInput& input,
                                           const std::vector<Rigid3>& world_from_cam,
                                           const CameraBlocks& cameras) {
  std::vector<Eigen::Vector3d> directions(layout.observations.size());
  for (size_t o = 0; o < layout.observations.size(); ++o) {
    const LayoutObservation& obs = layout.observations[o];
    const double pixel[2] = {input.keypoints[obs.image](obs.keypoint, 0),
                             input.keypoints[obs.image](obs.keypoint, 1)};
    const double* intrinsics = cameras.Of(obs.image).params.data();
    Eigen::Vector3d ray;
    ObservedPixelToUnitRay(intrinsics, pixel, ray.data());
    directions[o] = world_from_cam[obs.image].rotation * ray;
  }
  return directions;
}

// Depth along the source ray of the closest approach of the residual's two rays, when they meet
// in front of both cameras (0 otherwise).
double ClosestApproachDepth(const ProblemLayout& layout, const CrossProjection& residual,
                            const std::vector<Eigen::Vector3d>& directions,
                            const std::vector<Rigid3>& world_from_cam) {
  const int i = layout.observations[residual.source].image;
  const int j = layout.observations[residual.target].image;
  const Eigen::Vector3d& d1 = directions[residual.source];
  const Eigen::Vector3d& d2 = directions[residual.target];
  const Eigen::Vector3d w = world_from_cam[i].translation - world_from_cam[j].translation;
  // Closest approach of O_i + s·d1 and O_j + u·d2 (unit directions).
  const double b = d1.dot(d2);
  const double denom = 1.0 - b * b;
  if (denom < kMinSinSquared) return 0.0;
  const double d = d1.dot(w);
  const double e = d2.dot(w);
  const double s = (b * e - d) / denom;
  const double u = (e - b * d) / denom;
  return s > 0.0 && u > 0.0 ? s : 0.0;
}

}  // namespace

std::vector<double> InitialRayTimes(const ProblemLayout& layout, const RefineInput& input,
                                    const std::vector<Rigid3>& world_from_cam,
                                    const CameraBlocks& cameras, RayTimeInitMode mode,
                                    double constant, RayTimeInitSummary* summary) {
  summary->mode = NameOf(mode);
  const size_t num_ray_times = layout.ray_time_observation.size();
  if (mode == RayTimeInitMode::kConstant || num_ray_times == 0) {
    summary->min_depth = summary->median_depth = summary->max_depth = constant;
    return std::vector<double>(num_ray_times, constant);
  }

  // World-frame unit direction of every observation's ray under the prior.
  const std::vector<Eigen::Vector3d> directions =
      RayDirections(layout, input, world_from_cam, cameras);
  const size_t num_images = world_from_cam.size();
  std::vector<std::vector<double>> depths(num_images);
  std::vector<double> all_depths;
  for (const CrossProjection& residual : layout.residuals) {
    const double s = ClosestApproachDepth(layout, residual, directions, world_from_cam);
    if (s > 0.0) {
      depths[layout.observations[residual.source].image].push_back(s);
      all_depths.push_back(s);
    }
  }
  summary->num_depth_samples = static_cast<int>(all_depths.size());
  const double global = UpperMedian(all_depths, constant);

  std::vector<double> image_depth(num_images, global);
  std::vector<bool> image_has_ray_time(num_images, false);
  for (int o : layout.ray_time_observation) image_has_ray_time[layout.observations[o].image] = true;
  std::vector<double> used_depths;
  for (size_t i = 0; i < num_images; ++i) {
    if (!image_has_ray_time[i]) continue;
    if (depths[i].empty()) {
      ++summary->images_with_fallback;
    } else {
      image_depth[i] = UpperMedian(std::move(depths[i]), global);
    }
    used_depths.push_back(image_depth[i]);
  }
  summary->min_depth = *std::min_element(used_depths.begin(), used_depths.end());
  summary->max_depth = *std::max_element(used_depths.begin(), used_depths.end());
  summary->median_depth = UpperMedian(used_depths, constant);

  std::vector<double> ray_times(num_ray_times);
  for (size_t t = 0; t < num_ray_times; ++t) {
    ray_times[t] = image_depth[layout.observations[layout.ray_time_observation[t]].image];
  }
  return ray_times;
}

int StartRayTimesAtClosestApproach(const ProblemLayout& layout, const RefineInput& input,
                                   const std::vector<Rigid3>& world_from_cam,
                                   const CameraBlocks& cameras,
                                   const std::vector<bool>& needs_start,
                                   std::vector<double>* ray_times) {
  const std::vector<Eigen::Vector3d> directions =
      RayDirections(layout, input, world_from_cam, cameras);
  std::vector<std::vector<double>> depths(ray_times->size());
  for (const CrossProjection& residual : layout.residuals) {
    const int t = layout.observations[residual.source].ray_time;
    if (t < 0 || !needs_start[t]) continue;
    const double s = ClosestApproachDepth(layout, residual, directions, world_from_cam);
    if (s > 0.0) depths[t].push_back(s);
  }
  int started = 0;
  for (size_t t = 0; t < depths.size(); ++t) {
    if (depths[t].empty()) continue;
    (*ray_times)[t] = UpperMedian(std::move(depths[t]), (*ray_times)[t]);
    ++started;
  }
  return started;
}

double PriorDepthScale(const RefineInput& input, const std::vector<Rigid3>& world_from_cam,
                       const CameraBlocks& cameras, int max_matches_per_pair, int seed) {
  const ProblemLayout layout = BuildPerObservationLayout(input, max_matches_per_pair, seed);
  RayTimeInitSummary summary;
  InitialRayTimes(layout, input, world_from_cam, cameras, RayTimeInitMode::kAuto, 1.0, &summary);
  return summary.num_depth_samples > 0 && summary.median_depth > 0
             ? summary.median_depth
             : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace raytime
