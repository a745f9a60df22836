#include "refine/solve/problem_layout.h"

#include <algorithm>
#include <numeric>
#include <string>
#include <utility>

#include "core/camera.h"
#include "core/error.h"
#include "core/graph.h"

namespace raytime {
namespace {

uint64_t SplitMix64(uint64_t* state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Uniform integer in [0, n) by Lemire's multiply-shift (bias below 2^-32 for the sizes here).
uint64_t UniformBelow(uint64_t* state, uint64_t n) {
  return static_cast<uint64_t>((static_cast<unsigned __int128>(SplitMix64(state)) * n) >> 64);
}

uint64_t ObservationKey(int image, int keypoint) {
  return (static_cast<uint64_t>(image) << 32) | static_cast<uint32_t>(keypoint);
}

struct UsedMatches {
  std::vector<std::pair<uint64_t, uint64_t>> keys;  // (image, keypoint) keys of both ends
  std::vector<int> pairs;                           // per used match: index into input.pairs
  int num_input = 0;
};

// Validates the matches, skips pairs within one image, applies the cap.
UsedMatches CollectMatches(const RefineInput& input, int max_matches_per_pair, int seed) {
  const int num_images = static_cast<int>(input.keypoints.size());
  UsedMatches used;
  for (size_t p = 0; p < input.pairs.size(); ++p) {
    const PairMatchIndices& pair = input.pairs[p];
    if (pair.image1 < 0 || pair.image1 >= num_images || pair.image2 < 0 ||
        pair.image2 >= num_images) {
      throw InputError("refine: match pair (" + std::to_string(pair.image1) + ", " +
                       std::to_string(pair.image2) + ") names an image outside 0.." +
                       std::to_string(num_images - 1));
    }
    if (pair.image1 == pair.image2) continue;
    const int count = static_cast<int>(pair.matches.rows());
    used.num_input += count;
    const Eigen::Index rows1 = input.keypoints[pair.image1].rows();
    const Eigen::Index rows2 = input.keypoints[pair.image2].rows();
    for (int m : CappedMatchIndices(pair.image1, pair.image2, count, max_matches_per_pair, seed)) {
      const uint32_t k = pair.matches(m, 0);
      const uint32_t l = pair.matches(m, 1);
      if (k >= rows1 || l >= rows2) {
        throw InputError("refine: match " + std::to_string(m) + " of pair (" +
                         std::to_string(pair.image1) + ", " + std::to_string(pair.image2) +
                         ") names keypoint (" + std::to_string(k) + ", " + std::to_string(l) +
                         ") but the images have " + std::to_string(rows1) + " and " +
                         std::to_string(rows2) + " keypoints");
      }
      used.keys.emplace_back(ObservationKey(pair.image1, static_cast<int>(k)),
                             ObservationKey(pair.image2, static_cast<int>(l)));
      used.pairs.push_back(static_cast<int>(p));
    }
  }
  return used;
}

// Observations sorted by (image, keypoint), and each used match as a pair of their indices.
void IndexObservations(const UsedMatches& used, ProblemLayout* layout) {
  std::vector<uint64_t> keys;
  keys.reserve(2 * used.keys.size());
  for (const auto& [a, b] : used.keys) {
    keys.push_back(a);
    keys.push_back(b);
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  layout->observations.resize(keys.size());
  for (size_t o = 0; o < keys.size(); ++o) {
    layout->observations[o].image = static_cast<int>(keys[o] >> 32);
    layout->observations[o].keypoint = static_cast<int>(keys[o] & 0xffffffffu);
  }
  const auto index = [&keys](uint64_t key) {
    return static_cast<int>(std::lower_bound(keys.begin(), keys.end(), key) - keys.begin());
  };
  layout->matches.reserve(used.keys.size());
  for (size_t m = 0; m < used.keys.size(); ++m) {
    layout->matches.push_back(
        {used.pairs[m], index(used.keys[m].first), index(used.keys[m].second)});
  }
  layout->num_matches_used = static_cast<int>(used.keys.size());
  layout->num_matches_input = used.num_input;
}

}  // namespace

std::vector<int> CappedMatchIndices(int image1, int image2, int count, int cap, int seed) {
  std::vector<int> indices(count);
  std::iota(indices.begin(), indices.end(), 0);
  if (cap <= 0 || cap >= count) return indices;
  uint64_t state = static_cast<uint64_t>(static_cast<uint32_t>(seed));
  state = SplitMix64(&state) ^ ObservationKey(image1, image2);
  for (int i = 0; i < cap; ++i) {
    const int j = i + static_cast<int>(UniformBelow(&state, static_cast<uint64_t>(count - i)));
    std::swap(indices[i], indices[j]);
  }
  indices.resize(cap);
  std::sort(indices.begin(), indices.end());
  return indices;
}

ProblemLayout BuildPerObservationLayout(const RefineInput& input, int max_matches_per_pair,
                                        int seed) {
  ProblemLayout layout;
  IndexObservations(CollectMatches(input, max_matches_per_pair, seed), &layout);
  layout.ray_time_observation.resize(layout.observations.size());
  for (size_t o = 0; o < layout.observations.size(); ++o) {
    layout.observations[o].ray_time = static_cast<int>(o);
    layout.ray_time_observation[o] = static_cast<int>(o);
  }
  layout.residuals.reserve(2 * layout.matches.size());
  for (const LayoutMatch& match : layout.matches) {
    layout.residuals.push_back({match.observation1, match.observation2});
    layout.residuals.push_back({match.observation2, match.observation1});
  }
  return layout;
}

ProblemLayout BuildAnchoredLayout(const RefineInput& input, int max_matches_per_pair, int seed) {
  ProblemLayout layout;
  IndexObservations(CollectMatches(input, max_matches_per_pair, seed), &layout);
  const int n = static_cast<int>(layout.observations.size());
  // UnionFind keeps the smaller index as the root, so every root is its track's first
  // observation in (image, keypoint) order: that observation is the anchor.
  UnionFind tracks(n);
  for (const LayoutMatch& match : layout.matches) {
    tracks.Union(match.observation1, match.observation2);
  }
  // Observations are visited in index order, so each anchor precedes its track's members.
  for (int o = 0; o < n; ++o) {
    const int anchor = tracks.Find(o);
    if (anchor == o) continue;
    if (layout.observations[o].image == layout.observations[anchor].image) continue;
    LayoutObservation& anchor_obs = layout.observations[anchor];
    if (anchor_obs.ray_time < 0) {
      anchor_obs.ray_time = static_cast<int>(layout.ray_time_observation.size());
      layout.ray_time_observation.push_back(anchor);
    }
    layout.residuals.push_back({anchor, o});
  }
  layout.num_tracks = static_cast<int>(layout.ray_time_observation.size());
  // Residuals grouped by anchor, for memory locality of the cache reads.
  std::stable_sort(
      layout.residuals.begin(), layout.residuals.end(),
      [](const CrossProjection& x, const CrossProjection& y) { return x.source < y.source; });
  return layout;
}

std::vector<bool> ObservedImages(const ProblemLayout& layout, int num_images) {
  std::vector<bool> observed(num_images, false);
  for (const CrossProjection& residual : layout.residuals) {
    observed[layout.observations[residual.source].image] = true;
    observed[layout.observations[residual.target].image] = true;
  }
  return observed;
}

ObservationRays FixedObservationRays(const RefineInput& input, const ProblemLayout& layout,
                                     const CameraBlocks& cameras) {
  ObservationRays out;
  out.undistorted.resize(layout.observations.size());
  out.rays.resize(layout.observations.size());
  for (size_t o = 0; o < layout.observations.size(); ++o) {
    const LayoutObservation& obs = layout.observations[o];
    const double* intrinsics = cameras.Of(obs.image).params.data();
    const double pixel[2] = {input.keypoints[obs.image](obs.keypoint, 0),
                             input.keypoints[obs.image](obs.keypoint, 1)};
    ObservedPixelToUnitRay(intrinsics, pixel, out.rays[o].data(), out.undistorted[o].data());
  }
  return out;
}

}  // namespace raytime
