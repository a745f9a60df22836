// Focal length from the matches alone when the intrinsics are unknown (SPEC §4; paper §4.8
// "Refinement without an external prior": "classical focal search maximizing essential inlier
// counts, principal point at the image center").
#pragma once

#include <Eigen/Core>
#include <vector>
#include "core/options.h"

#include "bootstrap/relative_pose.h"

namespace raytime {

struct FocalSearchOptions {
  // Candidate focal lengths, as multiples of max(width, height), log-spaced.
  double focal_min_ratio = 0.4;
  double focal_max_ratio = 3.0;
  int focal_candidates = 24;
  // Log-spaced candidates between the neighbours of the best coarse candidate.
  int focal_refinements = 8;
  // The pairs with the most correspondences that are scored (the rest add time, not signal).
  int focal_pairs = 20;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("focal_min_ratio", focal_min_ratio,
      "Focal search: smallest candidate, multiple of max(width, height)", Positive(), AtMost(1000));
    v("focal_max_ratio", focal_max_ratio,
      "Focal search: largest candidate, multiple of max(width, height)", Positive(), AtMost(1000));
    v("focal_candidates", focal_candidates, "Focal search: log-spaced coarse candidates",
      AtLeast(2), AtMost(1e4));
    v("focal_refinements", focal_refinements,
      "Focal search: candidates between the best coarse one's neighbours", NonNegative(),
      AtMost(1e4));
    v("focal_pairs", focal_pairs, "Focal search: pairs with the most correspondences scored",
      Positive(), AtMost(1e5));
  }
  void CheckRelations(const Requirement& require) const {
    require(focal_max_ratio > focal_min_ratio, "focal_max_ratio must be above focal_min_ratio");
  }
};

// Pixel correspondences of one pair (columns match), OpenCV pixel convention.
struct PixelCorrespondences {
  Eigen::Matrix2Xd pixels1;
  Eigen::Matrix2Xd pixels2;
};

struct FocalSearchResult {
  double focal_px = 0.0;
  std::vector<double> candidates_px;  // every focal scored, in scoring order
  std::vector<int> inliers;           // summed five-point inliers per candidate
  int num_pairs = 0;                  // pairs scored
};

// Scores every candidate by the summed five-point RANSAC inlier counts of the scored pairs, with
// rays from an ideal pinhole (fx = fy = f, principal point at the image centre, no distortion).
// Throws InputError without any pair of >= relative_pose.min_inliers correspondences.
FocalSearchResult SearchFocal(const std::vector<PixelCorrespondences>& pairs, int width, int height,
                              const FocalSearchOptions& options,
                              const RelativePoseOptions& relative_pose);

}  // namespace raytime
