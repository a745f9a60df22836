// Pairwise matching and geometric verification of a set of images (SPEC §5, paper §4.1).
//
// Per image pair: nearest-neighbour matching with the ratio test and mutual check
// (descriptor_matching.h), robust two-view geometry on the putative matches
// (two_view_geometry.h), then guided matching: a second matching pass in which each keypoint only
// competes with keypoints near its epipolar line under the estimated F, verified again. Pairs
// with fewer than min_num_inliers verified inliers are dropped. No pose prior enters: the pairs
// come from the image list alone (all pairs, or a window along the name order plus a keyframe
// grid for loop closures), or are handed over as a list (`pairs: prior`: the matches stage chooses
// them from the prior's poses, pipelines/pair_selection.h); matching and verification never see a
// pose.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/features.h"
#include "core/options.h"
#include "core/types.h"

namespace raytime {

struct MatchingOptions {
  // "exhaustive": every pair (the paper's setting, O(N^2)). "sequential": images in name order
  // (video frames), each with the next `window` images, plus loop candidates (below). "prior":
  // the pairs the matches stage chooses from the prior's poses (SPEC §5, O(N k)), handed to
  // MatchImagePairs; MatchImages refuses it.
  std::string pairs = "exhaustive";
  int window = 10;  // sequential: neighbours matched after each image
  // Sequential loop candidates: every pair of keyframes (images whose index in name order is a
  // multiple of loop_stride) further apart than the window, so returning to a place is matched
  // without any pose prior. 0 disables.
  int loop_stride = 0;
  // Lowe's ratio test on descriptor distances (COLMAP's SiftMatching.max_ratio).
  double max_ratio = 0.8;
  // Largest descriptor distance of a match (L2 between unit descriptors; 0.7 is about COLMAP's
  // SiftMatching.max_distance of 0.7 rad). Matters for guided matching, where a keypoint with a
  // single candidate passes any ratio test.
  double max_distance = 0.7;
  // Keep a match only when each keypoint is the other's nearest neighbour and both pass the
  // ratio test (COLMAP's SiftMatching.cross_check).
  bool mutual_check = true;
  // Descriptor product kernel: "auto" (the fastest this CPU has), "vnni", "avx2", "gemm"
  // (portable); all find the same matches. The choice and its measurement: descriptor_matching.h.
  std::string kernel = "auto";
  // "auto": essential matrix when the pair's cameras have a focal length, fundamental otherwise;
  // "essential" (an image without intrinsics is an error) or "fundamental".
  std::string geometry = "auto";
  // Robust estimator: "magsac" (OpenCV USAC_MAGSAC, MAGSAC++) or "ransac" (OpenCV RANSAC).
  std::string estimator = "magsac";
  // Threshold of the robust estimator, pixels (Sampson distance). Measured on fountain-P11
  // (1536x1024, 55 pairs, MAGSAC++): 90th percentile of the relative rotation error over pairs
  // 0.22° at 0.5 px, 0.29° at 1 px, 0.39° at 2 px, 0.50° at 4 px, where one facade pair also
  // came out 34° wrong (a near-planar scene leaves a second essential matrix inside a 4 px
  // band); the verified inliers (counted at max_error_px) barely change.
  double ransac_error_px = 1.0;
  // Inlier threshold of the polished model and half-width of the guided matching band, pixels
  // (Sampson distance; COLMAP's SiftMatching.max_error).
  double max_error_px = 4.0;
  double confidence = 0.999;   // RANSAC stopping confidence (COLMAP: 0.999)
  int max_iterations = 10000;  // RANSAC iteration cap (COLMAP's max_num_trials)
  int min_num_inliers = 15;    // pairs verified by fewer are dropped (COLMAP's default)
  // Second matching pass restricted to candidates within max_error_px (Sampson distance) of the
  // epipolar line under the estimated F, then verified again (COLMAP's guided_matching).
  bool guided_matching = true;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("pairs", pairs,
      "Pairs to match: every pair, name-order neighbours (video), or chosen from the prior's "
      "poses (the prior stage must come first)",
      OneOf({"exhaustive", "sequential", "prior"}));
    v("window", window, "Sequential: neighbours matched after each image", Positive(), AtMost(1e6));
    v("loop_stride", loop_stride,
      "Sequential: keyframe stride of loop-closure candidates; 0 disables", NonNegative(),
      AtMost(1e6));
    v("max_ratio", max_ratio, "Lowe's ratio test on descriptor distances (COLMAP: 0.8)", Positive(),
      AtMost(1));
    v("max_distance", max_distance, "Largest descriptor distance of a match (unit descriptors)",
      Positive(), AtMost(2));
    v("mutual_check", mutual_check, "Keep only mutual nearest neighbours (COLMAP's cross_check)");
    v("kernel", kernel, "Descriptor product kernel (auto: VNNI, else AVX2, else portable)",
      OneOf({"auto", "vnni", "avx2", "gemm"}));
    v("geometry", geometry,
      "Verification model: auto = essential when the focal is known, else fundamental",
      OneOf({"auto", "essential", "fundamental"}));
    v("estimator", estimator, "Robust estimator (OpenCV MAGSAC++ or RANSAC)",
      OneOf({"magsac", "ransac"}));
    v("ransac_error_px", ransac_error_px, "Robust estimator threshold, pixels (Sampson distance)",
      Positive(), AtMost(1000));
    v("max_error_px", max_error_px,
      "Inlier threshold and guided-matching band, pixels (COLMAP's max_error)", Positive(),
      AtMost(1000));
    v("confidence", confidence, "RANSAC stopping confidence (COLMAP: 0.999)", Positive(), Below(1));
    v("max_iterations", max_iterations, "RANSAC iteration cap (COLMAP's max_num_trials)",
      Positive(), AtMost(1e7));
    v("min_num_inliers", min_num_inliers,
      "Pairs with fewer verified inliers are dropped (COLMAP: 15; estimators need 8)", AtLeast(8),
      AtMost(1e6));
    v("guided_matching", guided_matching,
      "Second matching pass within max_error_px of the epipolar lines, then verified again");
  }
};

struct MatchingSummary {
  int num_images = 0;
  int num_pairs = 0;           // candidate pairs matched
  int num_verified_pairs = 0;  // kept: at least min_num_inliers inliers
  int num_dropped_pairs = 0;   // num_pairs - num_verified_pairs
  int64_t num_putative = 0;    // first-pass putative matches over all candidate pairs
  int64_t num_inliers = 0;     // verified inliers over the kept pairs (after guided matching)
  int64_t num_inliers_first_pass = 0;  // the same before guided matching
  std::string kernel;                  // descriptor kernel that ran
  double seconds = 0;                  // wall clock
  // Thread time summed over pairs, per step (exceeds `seconds` when pairs run in parallel).
  double matching_thread_seconds = 0;
  double verification_thread_seconds = 0;
  double guided_thread_seconds = 0;

  nlohmann::json ToJson() const;  // the fields by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(MatchingSummary, num_images, num_pairs, num_verified_pairs,
                                   num_dropped_pairs, num_putative, num_inliers,
                                   num_inliers_first_pass, kernel, seconds, matching_thread_seconds,
                                   verification_thread_seconds, guided_thread_seconds)

// One candidate pair's outcome, kept or dropped: what a caller needs to stand in for matching the
// pair again (the pipelines keep it per pair, issue 34).
struct CandidatePairOutcome {
  bool kept = false;                   // at least min_num_inliers verified inliers
  int64_t num_putative = 0;            // first-pass putative matches
  int64_t num_inliers_first_pass = 0;  // verified inliers before guided matching
};

// Candidate pairs (i < j, indices into the image list), sorted, for pairs "exhaustive" and
// "sequential"; InputError for "prior" (chosen by the caller from poses).
std::vector<std::pair<int, int>> SelectPairs(int num_images, const MatchingOptions& options);

// Matches and verifies the given candidate pairs of `images` (i < j, indices into the image list,
// sorted, no duplicates; otherwise an InputError), in parallel over pairs. features[i] belongs to
// images.images[i]. Output: the kept pairs sorted by (image1, image2); `matches` holds the
// first-pass putative matches plus the guided ones (so inlier_matches is a subset of it).
// Keypoints are undistorted (core/camera.h) before estimation when the camera has distortion;
// the stored indices refer to the original keypoints. `outcomes` (optional) receives one entry
// per candidate, in the candidates' order. A pair's result depends on its two images' features and
// cameras and the options only (the robust estimators start from a fixed seed per pair).
MatchingSummary MatchImagePairs(const ImageSet& images, const std::vector<ImageFeatures>& features,
                                const MatchingOptions& options,
                                const std::vector<std::pair<int, int>>& candidates,
                                std::vector<PairMatches>* pairs,
                                std::vector<CandidatePairOutcome>* outcomes = nullptr);

// MatchImagePairs on SelectPairs(options).
MatchingSummary MatchImages(const ImageSet& images, const std::vector<ImageFeatures>& features,
                            const MatchingOptions& options, std::vector<PairMatches>* pairs);

}  // namespace raytime
