#include "frontend/matching.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>

#include "core/camera.h"
#include "core/error.h"
#include "core/options.h"
#include "core/progress.h"
#include "core/timing.h"
#include "frontend/descriptor_matching.h"
#include "frontend/two_view_geometry.h"

namespace raytime {
namespace {

using Clock = std::chrono::steady_clock;

bool HasFocal(const CameraIntrinsics& camera) { return camera.fx() > 0 && camera.fy() > 0; }

Eigen::Matrix3d PinholeMatrix(const CameraIntrinsics& camera) {
  Eigen::Matrix3d K;
  K << camera.fx(), 0, camera.cx(), 0, camera.fy(), camera.cy(), 0, 0, 1;
  return K;
}

// Keypoint positions in the frame the two-view geometry lives in: undistorted pixels when the
// camera has distortion (paper §3.2), the keypoints themselves otherwise.
PointList GeometryPoints(const ImageFeatures& features, const CameraIntrinsics& camera) {
  PointList points(features.keypoints.rows(), 2);
  for (Eigen::Index k = 0; k < points.rows(); ++k) {
    const double distorted[2] = {features.keypoints(k, 0), features.keypoints(k, 1)};
    if (camera.HasDistortion() && HasFocal(camera)) {
      double undistorted[2];
      UndistortPixel(camera.params.data(), distorted, undistorted);
      points(k, 0) = undistorted[0];
      points(k, 1) = undistorted[1];
    } else {
      points(k, 0) = distorted[0];
      points(k, 1) = distorted[1];
    }
  }
  return points;
}

PointList Select(const PointList& points, const MatchList& matches, int column) {
  PointList out(matches.rows(), 2);
  for (Eigen::Index k = 0; k < matches.rows(); ++k) out.row(k) = points.row(matches(k, column));
  return out;
}

MatchList SelectRows(const MatchList& matches, const std::vector<int>& rows) {
  MatchList out(rows.size(), 2);
  for (size_t k = 0; k < rows.size(); ++k) out.row(k) = matches.row(rows[k]);
  return out;
}

MatchList SortedUnion(const MatchList& a, const MatchList& b) {
  std::vector<std::pair<uint32_t, uint32_t>> all;
  all.reserve(a.rows() + b.rows());
  for (Eigen::Index k = 0; k < a.rows(); ++k) all.emplace_back(a(k, 0), a(k, 1));
  for (Eigen::Index k = 0; k < b.rows(); ++k) all.emplace_back(b(k, 0), b(k, 1));
  std::sort(all.begin(), all.end());
  all.erase(std::unique(all.begin(), all.end()), all.end());
  MatchList out(all.size(), 2);
  for (size_t k = 0; k < all.size(); ++k) {
    out(k, 0) = all[k].first;
    out(k, 1) = all[k].second;
  }
  return out;
}

struct PairStats {
  bool kept = false;
  int64_t num_putative = 0;
  int64_t num_inliers_first_pass = 0;
  double matching_seconds = 0;
  double verification_seconds = 0;
  double guided_seconds = 0;
};

struct PairInput {
  const ImageFeatures* features1;
  const ImageFeatures* features2;
  const CameraIntrinsics* camera1;
  const CameraIntrinsics* camera2;
  bool calibrated;
};

void MatchPair(const PairInput& in, const MatchingOptions& options, MatchKernel kernel,
               RobustEstimator estimator, PairMatches* out, PairStats* stats) {
  auto start = Clock::now();
  const ByteDescriptors& d1 = in.features1->descriptors;
  const ByteDescriptors& d2 = in.features2->descriptors;
  NeighborList a_to_b, b_to_a;
  FindNeighbors(d1, d2, kernel, &a_to_b, &b_to_a);
  const MatchList putative = RatioTestMatches(a_to_b, b_to_a, options.max_ratio,
                                              options.max_distance, options.mutual_check);
  stats->num_putative = putative.rows();
  stats->matching_seconds = SecondsSince(start);

  start = Clock::now();
  const PointList x1 = GeometryPoints(*in.features1, *in.camera1);
  const PointList x2 = GeometryPoints(*in.features2, *in.camera2);
  Eigen::Matrix3d K1, K2;
  if (in.calibrated) {
    K1 = PinholeMatrix(*in.camera1);
    K2 = PinholeMatrix(*in.camera2);
  }
  const auto estimate = [&](const MatchList& matches) {
    return EstimateTwoViewGeometry(Select(x1, matches, 0), Select(x2, matches, 1),
                                   in.calibrated ? &K1 : nullptr, in.calibrated ? &K2 : nullptr,
                                   estimator, options.ransac_error_px, options.max_error_px,
                                   options.confidence, options.max_iterations);
  };
  GeometryEstimate geometry = estimate(putative);
  MatchList inliers = SelectRows(putative, geometry.inliers);
  stats->num_inliers_first_pass = inliers.rows();
  stats->verification_seconds = SecondsSince(start);

  out->matches = putative;
  if (options.guided_matching && inliers.rows() >= options.min_num_inliers) {
    start = Clock::now();
    const MatchList guided =
        GuidedMatches(d1, d2, x1, x2, geometry.geometry.F, options.max_error_px, options.max_ratio,
                      options.max_distance, options.mutual_check, kernel);
    GeometryEstimate guided_geometry = estimate(guided);
    // The guided pass sees a superset of candidates for every keypoint near its epipolar line,
    // so it normally verifies more; keep the first pass if it does not.
    if (guided_geometry.inliers.size() >= geometry.inliers.size()) {
      inliers = SelectRows(guided, guided_geometry.inliers);
      geometry = std::move(guided_geometry);
    }
    out->matches = SortedUnion(putative, guided);
    stats->guided_seconds = SecondsSince(start);
  }
  out->geometry = geometry.geometry;
  out->geometry.inlier_matches = inliers;
  stats->kept = inliers.rows() >= options.min_num_inliers;
}

}  // namespace

nlohmann::json MatchingSummary::ToJson() const { return *this; }

std::vector<std::pair<int, int>> SelectPairs(int num_images, const MatchingOptions& options) {
  if (options.pairs == "prior") {
    throw InputError(
        "matching: pairs 'prior' are chosen from the prior's poses by the matches stage "
        "(pipelines/pair_selection.h) and handed to MatchImagePairs");
  }
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < num_images; ++i) {
    for (int j = i + 1; j < num_images; ++j) {
      const bool in_window = j - i <= options.window;
      const bool keyframes =
          options.loop_stride > 0 && i % options.loop_stride == 0 && j % options.loop_stride == 0;
      if (options.pairs == "exhaustive" || in_window || keyframes) pairs.emplace_back(i, j);
    }
  }
  return pairs;
}

MatchingSummary MatchImages(const ImageSet& images, const std::vector<ImageFeatures>& features,
                            const MatchingOptions& options, std::vector<PairMatches>* pairs) {
  ValidateOptions(options, "matching");
  return MatchImagePairs(images, features, options,
                         SelectPairs(static_cast<int>(images.images.size()), options), pairs);
}

MatchingSummary MatchImagePairs(const ImageSet& images, const std::vector<ImageFeatures>& features,
                                const MatchingOptions& options,
                                const std::vector<std::pair<int, int>>& candidates,
                                std::vector<PairMatches>* pairs,
                                std::vector<CandidatePairOutcome>* outcomes) {
  ValidateOptions(options, "matching");
  const auto start = Clock::now();
  const int num_images = static_cast<int>(images.images.size());
  if (static_cast<int>(features.size()) != num_images) {
    throw InputError("matching: " + std::to_string(features.size()) + " feature sets for " +
                     std::to_string(num_images) +
                     " images (features and images come from "
                     "different runs?)");
  }
  const MatchKernel kernel = ResolveMatchKernel(ParseMatchKernel(options.kernel, "kernel"));
  const RobustEstimator estimator = ParseRobustEstimator(options.estimator, "estimator");
  for (int i = 0; i < num_images; ++i) {
    const CameraIntrinsics& camera = images.cameras.at(images.images[i].camera_index);
    if (options.geometry == "essential" && !HasFocal(camera)) {
      throw InputError("matching: geometry is 'essential' but image " + images.images[i].name +
                       " has no focal length (use geometry: fundamental or auto)");
    }
    if (features[i].descriptors.rows() != features[i].keypoints.rows()) {
      throw InputError("matching: image " + images.images[i].name + " has " +
                       std::to_string(features[i].keypoints.rows()) + " keypoints but " +
                       std::to_string(features[i].descriptors.rows()) + " descriptors");
    }
  }

  for (size_t p = 0; p < candidates.size(); ++p) {
    const auto [i, j] = candidates[p];
    if (i < 0 || i >= j || j >= num_images || (p > 0 && candidates[p - 1] >= candidates[p])) {
      throw InputError("matching: candidate pair " + std::to_string(p) + " (" + std::to_string(i) +
                       ", " + std::to_string(j) + ") of " + std::to_string(num_images) +
                       " images is not an ordered pair of valid indices in sorted order");
    }
  }
  const int num_pairs = static_cast<int>(candidates.size());
  std::vector<PairMatches> results(num_pairs);
  std::vector<PairStats> stats(num_pairs);
  // Progress every ~5 % of the pairs (at least every pair for small sets).
  const int block = std::max(1, num_pairs / 20);
  std::atomic<int> done{0}, kept{0};
  std::mutex log_mutex;
  spdlog::info(fmt::format("matches: {} pairs of {} images ({}, {} kernel)", num_pairs, num_images,
                           options.pairs, MatchKernelName(kernel)));
  ProgressBar bar("matches", num_pairs);
  tbb::parallel_for(0, num_pairs, [&](int p) {
    const auto [i, j] = candidates[p];
    const CameraIntrinsics& camera1 = images.cameras.at(images.images[i].camera_index);
    const CameraIntrinsics& camera2 = images.cameras.at(images.images[j].camera_index);
    PairInput input{&features[i], &features[j], &camera1, &camera2,
                    options.geometry != "fundamental" && HasFocal(camera1) && HasFocal(camera2)};
    results[p].image1 = i;
    results[p].image2 = j;
    MatchPair(input, options, kernel, estimator, &results[p], &stats[p]);
    if (stats[p].kept) ++kept;
    const int finished = ++done;
    bar.Update(finished, std::to_string(kept.load()) + " verified");
    if (!bar.drawing() && (finished % block == 0 || finished == num_pairs)) {
      std::lock_guard<std::mutex> lock(log_mutex);
      spdlog::info(fmt::format("matches: {}/{} pairs, {} verified, {:.1f} s", finished, num_pairs,
                               kept.load(), SecondsSince(start)));
    }
  });

  MatchingSummary summary;
  summary.num_images = num_images;
  summary.num_pairs = num_pairs;
  summary.kernel = MatchKernelName(kernel);
  pairs->clear();
  if (outcomes != nullptr) outcomes->assign(num_pairs, CandidatePairOutcome());
  for (int p = 0; p < num_pairs; ++p) {
    if (outcomes != nullptr) {
      (*outcomes)[p] = {stats[p].kept, stats[p].num_putative, stats[p].num_inliers_first_pass};
    }
    summary.num_putative += stats[p].num_putative;
    summary.matching_thread_seconds += stats[p].matching_seconds;
    summary.verification_thread_seconds += stats[p].verification_seconds;
    summary.guided_thread_seconds += stats[p].guided_seconds;
    if (!stats[p].kept) continue;
    summary.num_inliers += results[p].geometry.inlier_matches.rows();
    summary.num_inliers_first_pass += stats[p].num_inliers_first_pass;
    pairs->push_back(std::move(results[p]));
  }
  summary.num_verified_pairs = static_cast<int>(pairs->size());
  summary.num_dropped_pairs = num_pairs - summary.num_verified_pairs;
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace raytime
