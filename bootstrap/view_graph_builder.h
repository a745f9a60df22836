// Relative poses of every verified pair of a match file (SPEC §4; paper §4.8): bearings from the
// undistorted keypoints of the stored inlier correspondences, optionally a focal search first.
#pragma once

#include <vector>

#include "bootstrap/focal_search.h"
#include "bootstrap/relative_pose.h"
#include "bootstrap/view_graph.h"
#include "core/features.h"
#include "core/types.h"

namespace raytime {

struct ViewGraphBuildResult {
  std::vector<ViewGraphEdge> edges;               // one per pair with at least one verified inlier
  std::vector<CameraIntrinsics> cameras;          // the intrinsics the bearings were computed with
  std::vector<FocalSearchResult> focal_searches;  // per camera, when the focal was searched
  int num_pairs_input = 0;
};

// `features[i]` belongs to `images.images[i]`; pairs index the same list. With `focal_search`,
// every camera's focal is searched (fx = fy, principal point at the image centre, distortion
// dropped) on the pairs between its own images. Throws std::invalid_argument naming the pair or
// image on inconsistent input (index or keypoint row out of range, sizes that disagree).
ViewGraphBuildResult BuildViewGraph(const ImageSet& images,
                                    const std::vector<ImageFeatures>& features,
                                    const std::vector<PairMatches>& matches,
                                    const RelativePoseOptions& relative_pose, bool focal_search,
                                    const FocalSearchOptions& focal_options);

}  // namespace raytime
