#include "refine/checks/frame_doubt.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <stdexcept>
#include <utility>

#include "core/statistics.h"
#include "refine/checks/guardrails.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {
namespace {

// Matches sampled per pair for its median: enough for a median to a few percent, and memory that
// does not grow with a capture's tens of millions of matches.
constexpr int kSamplesPerPair = 200;

// Undistorted pixel and unit ray of one observation.
struct DoubtedObservationRay {
  Eigen::Vector2d pixel;
  Eigen::Vector3d ray;
};

DoubtedObservationRay DoubtedObservationRayOf(const CameraIntrinsics& camera,
                                              const Eigen::Vector2d& observed) {
  DoubtedObservationRay out;
  ObservedPixelToUnitRay(camera.params.data(), observed.data(), out.ray.data(), out.pixel.data());
  return out;
}

// |π_target(O_s + t R_s d_s) - û_target|, pixels; NaN without a positive ray time.
double CrossProjectionAtRayTime(const Rigid3& source_pose, const DoubtedObservationRay& source,
                                double ray_time, const Rigid3& target_pose,
                                const CameraIntrinsics& target_camera,
                                const DoubtedObservationRay& target) {
  if (!(ray_time > 0)) return std::numeric_limits<double>::quiet_NaN();
  // Row-major rotations, as refine/solve/ray_geometry.h takes them (Eigen's default is
  // column-major).
  using RowMajor = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  const RowMajor source_rotation = source_pose.rotation.toRotationMatrix();
  const RowMajor target_rotation = target_pose.rotation.toRotationMatrix();
  double direction[3], point[3], offset[3], p_cam[3];
  RayPoint(source_rotation.data(), source_pose.translation.data(), ray_time, source.ray.data(),
           direction, point);
  Eigen::Vector2d residual;
  TargetResidual(target_rotation.data(), target_pose.translation.data(),
                 target_camera.params.data(), point, target.pixel.data(), offset, p_cam,
                 residual.data());
  return residual.norm();
}

}  // namespace

FrameDoubtVerdict CheckFrameDoubts(
    const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
    const std::vector<CameraIntrinsics>& intrinsics, const Eigen::VectorXi& observation_image,
    const Eigen::Matrix<double, Eigen::Dynamic, 2>& observation_pixel,
    const Eigen::VectorXd& ray_times,
    const Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>& matches,
    const FrameDoubtOptions& options) {
  const int n = static_cast<int>(prior.size());
  if (solution.size() != prior.size() || intrinsics.size() != prior.size() ||
      observation_pixel.rows() != observation_image.size() ||
      ray_times.size() != observation_image.size()) {
    throw std::invalid_argument("CheckFrameDoubts: inconsistent sizes");
  }
  FrameDoubtVerdict verdict;
  verdict.centre_change.assign(n, std::numeric_limits<double>::quiet_NaN());
  verdict.residual_ratio.assign(n, std::numeric_limits<double>::quiet_NaN());

  // Corrections after a Sim(3) fit of the solution onto the prior (a gauge change is no
  // correction); the prior's extent is its centres' median distance from their centroid.
  if (!CentreChangesAfterSim3(prior, solution, &verdict.centre_change)) return verdict;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : prior) centroid += pose.translation / n;
  std::vector<double> extent;
  for (const Rigid3& pose : prior) extent.push_back((pose.translation - centroid).norm());
  verdict.median_centre_change = Median(verdict.centre_change, 0.0);
  verdict.centre_change_threshold =
      std::max(options.centre_change_factor * verdict.median_centre_change,
               options.min_centre_change_fraction * Median(extent, 0.0));

  // Per pair: a sample of its matches' cross-projection residuals (root mean square of the two
  // directions), in match order.
  struct PairSample {
    int count = 0;
    int seen = 0;
    std::vector<double> values;
  };
  std::map<std::pair<int, int>, PairSample> pairs;
  const auto key = [&](Eigen::Index m) {
    const int a = observation_image(matches(m, 0)), b = observation_image(matches(m, 1));
    return std::make_pair(std::min(a, b), std::max(a, b));
  };
  for (Eigen::Index m = 0; m < matches.rows(); ++m) ++pairs[key(m)].count;
  for (Eigen::Index m = 0; m < matches.rows(); ++m) {
    PairSample& pair = pairs[key(m)];
    const int stride = std::max(1, pair.count / kSamplesPerPair);
    if (pair.seen++ % stride != 0) continue;
    const int oa = matches(m, 0), ob = matches(m, 1);
    const int a = observation_image(oa), b = observation_image(ob);
    const DoubtedObservationRay ra =
        DoubtedObservationRayOf(intrinsics[a], observation_pixel.row(oa).transpose());
    const DoubtedObservationRay rb =
        DoubtedObservationRayOf(intrinsics[b], observation_pixel.row(ob).transpose());
    const double ab =
        CrossProjectionAtRayTime(solution[a], ra, ray_times(oa), solution[b], intrinsics[b], rb);
    const double ba =
        CrossProjectionAtRayTime(solution[b], rb, ray_times(ob), solution[a], intrinsics[a], ra);
    double value = std::numeric_limits<double>::quiet_NaN();
    if (std::isfinite(ab) && std::isfinite(ba)) {
      value = std::sqrt(0.5 * (ab * ab + ba * ba));
    } else if (std::isfinite(ab) || std::isfinite(ba)) {
      value = std::isfinite(ab) ? ab : ba;
    }
    if (std::isfinite(value)) pair.values.push_back(value);
  }
  std::vector<double> all_pairs;
  std::vector<std::vector<std::pair<int, double>>> of_image(n);  // (other image, pair median)
  for (const auto& [images, sample] : pairs) {
    if (sample.values.empty()) continue;
    const double median = Median(sample.values, 0.0);
    all_pairs.push_back(median);
    of_image[images.first].emplace_back(images.second, median);
    of_image[images.second].emplace_back(images.first, median);
  }
  if (all_pairs.empty()) return verdict;
  verdict.checked = true;
  verdict.median_pair_residual_px = Median(all_pairs, 0.0);
  if (!(verdict.median_pair_residual_px > 0)) return verdict;
  // A frame's ratio over its pairs with frames not in `out`.
  const auto ratio = [&](int i, const std::vector<bool>& out) {
    std::vector<double> medians;
    for (const auto& [other, median] : of_image[i]) {
      if (!out[other]) medians.push_back(median);
    }
    return medians.empty() ? std::numeric_limits<double>::quiet_NaN()
                           : Median(medians, 0.0) / verdict.median_pair_residual_px;
  };
  std::vector<bool> none(n, false), doubted(n, false);
  for (int i = 0; i < n; ++i) {
    verdict.residual_ratio[i] = ratio(i, none);
    doubted[i] = verdict.centre_change[i] > verdict.centre_change_threshold &&
                 verdict.residual_ratio[i] > options.residual_ratio;
  }
  // Fitting far worse alone, worst first: a frame's pairs with a frame already doubted do not
  // count against it (a neighbour of a misplaced frame fits its pairs with it badly too).
  while (true) {
    int worst = -1;
    double worst_ratio = options.far_residual_ratio;
    for (int i = 0; i < n; ++i) {
      if (doubted[i]) continue;
      const double r = ratio(i, doubted);
      if (r > worst_ratio) {
        worst = i;
        worst_ratio = r;
      }
    }
    if (worst < 0) break;
    doubted[worst] = true;
  }
  for (int i = 0; i < n; ++i) {
    if (doubted[i]) verdict.images.push_back(i);
  }
  return verdict;
}

}  // namespace raytime
