#include "bootstrap/focal_search.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "core/error.h"

namespace raytime {
namespace {

Eigen::Matrix3Xd Rays(const Eigen::Matrix2Xd& pixels, const Eigen::Vector2d& centre, double f) {
  Eigen::Matrix3Xd rays(3, pixels.cols());
  for (Eigen::Index k = 0; k < pixels.cols(); ++k) {
    rays.col(k) =
        Eigen::Vector3d((pixels(0, k) - centre.x()) / f, (pixels(1, k) - centre.y()) / f, 1.0)
            .normalized();
  }
  return rays;
}

// Indices of the first and last candidate (in focal order) reaching the highest count: on clean
// matches a range of focal lengths explains every correspondence, and the middle of that plateau
// is the unbiased pick where the first maximum would favour its short end.
std::pair<size_t, size_t> Plateau(const std::vector<double>& focal, const std::vector<int>& count) {
  std::vector<size_t> order(focal.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return focal[a] < focal[b]; });
  const int best = *std::max_element(count.begin(), count.end());
  size_t first = order.size(), last = 0;
  for (size_t k = 0; k < order.size(); ++k) {
    if (count[order[k]] == best) {
      first = std::min(first, k);
      last = k;
    }
  }
  return {order[first], order[last]};
}

std::vector<double> LogSpaced(double lo, double hi, int count) {
  std::vector<double> values;
  for (int k = 0; k < count; ++k) {
    const double t = count == 1 ? 0.5 : static_cast<double>(k) / (count - 1);
    values.push_back(lo * std::pow(hi / lo, t));
  }
  return values;
}

}  // namespace

FocalSearchResult SearchFocal(const std::vector<PixelCorrespondences>& pairs, int width, int height,
                              const FocalSearchOptions& options,
                              const RelativePoseOptions& relative_pose) {
  ValidateOptions(options, "focal search");
  ValidateOptions(relative_pose, "relative pose");
  if (width <= 0 || height <= 0) throw std::invalid_argument("focal search: bad image size");
  std::vector<int> order;
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (pairs[k].pixels1.cols() != pairs[k].pixels2.cols()) {
      throw std::invalid_argument("focal search: pair " + std::to_string(k) +
                                  " has unequal correspondence counts");
    }
    if (pairs[k].pixels1.cols() >= relative_pose.min_inliers) order.push_back(static_cast<int>(k));
  }
  if (order.empty()) {
    throw InputError("focal search: no pair has " + std::to_string(relative_pose.min_inliers) +
                     " correspondences or more");
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return pairs[a].pixels1.cols() > pairs[b].pixels1.cols(); });
  order.resize(std::min<size_t>(order.size(), options.focal_pairs));

  const Eigen::Vector2d centre((width - 1) / 2.0, (height - 1) / 2.0);  // OpenCV pixel centres
  const double size = std::max(width, height);
  FocalSearchResult result;
  result.num_pairs = static_cast<int>(order.size());
  auto score = [&](double f) {
    std::vector<int> counts(order.size(), 0);
    tbb::parallel_for(size_t(0), order.size(), [&](size_t k) {
      const PixelCorrespondences& pair = pairs[order[k]];
      const RelativePoseResult pose = EstimateRelativePose(
          Rays(pair.pixels1, centre, f), Rays(pair.pixels2, centre, f), f, relative_pose);
      counts[k] = static_cast<int>(pose.inliers.size());
    });
    result.candidates_px.push_back(f);
    result.inliers.push_back(std::accumulate(counts.begin(), counts.end(), 0));
  };
  const std::vector<double> coarse = LogSpaced(
      options.focal_min_ratio * size, options.focal_max_ratio * size, options.focal_candidates);
  for (double f : coarse) score(f);
  if (options.focal_refinements > 0) {
    // Refine over the coarse plateau widened by one coarse step on each side (coarse is sorted).
    const auto [first, last] = Plateau(result.candidates_px, result.inliers);
    const double lo = coarse[first > 0 ? first - 1 : 0];
    const double hi = coarse[std::min<size_t>(last + 1, coarse.size() - 1)];
    // Interior points only: the ends were scored on the coarse grid.
    const std::vector<double> fine = LogSpaced(lo, hi, options.focal_refinements + 2);
    for (size_t k = 1; k + 1 < fine.size(); ++k) score(fine[k]);
  }
  const auto [first, last] = Plateau(result.candidates_px, result.inliers);
  result.focal_px = std::sqrt(result.candidates_px[first] * result.candidates_px[last]);
  return result;
}

}  // namespace raytime
