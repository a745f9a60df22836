// Prior-guided pair selection (SPEC §5: "for long captures the prior may choose which pairs are
// matched"; issue 10 "Prior-guided pairs"). The paper matches every pair (§4.1 Setup); a capture of
// hundreds of frames cannot afford that, so the prior's poses choose, for every image, the k
// partners whose view overlaps it most, joined with a sequential window for video-ordered frames.
// The prior only chooses which pairs are matched: matching and verification never see it.
//
// View overlap of a pair (i, j), from the cameras alone (no structure): image i is sampled on a
// pixel grid at three depths along its optical axis (half, once and twice its scene depth); a
// sample counts when it lands inside image j, in front of camera j, and at a resolution within
// max_scale_ratio of image i's (SIFT matches poorly across larger scale changes), weighted by
// 1 - a / max_angle_deg, where a is the angle between the two cameras' rays to it: the viewpoint
// change matching must bridge (SIFT's repeatability falls roughly linearly with viewpoint change,
// to little beyond 60-70°: Mikolajczyk et al., "A comparison of affine region detectors", IJCV
// 2005, Fig. 13). Without the weight every camera of an orbit looking at its centre would
// "overlap" almost fully. The overlap is the mean of the scores i -> j and j -> i, so it is
// symmetric and lies in [0, 1]. Pairs whose optical axes are more than max_angle_deg apart are
// never chosen (opposite cameras see the other side of the object). Cost: one pass over all pairs
// of cheap projections, O(N^2 x samples), once; matching then costs O(N k).
//
// Scene depth (per image): given, or "auto": the median over the other cameras of the depth along
// this camera's optical axis at which it passes closest to theirs, counting axis pairs at least
// kMinAxisAngleDeg apart that meet in front of both (for a ring of cameras looking at an object:
// the distance to its centre). An image with no such sample takes the median of all samples; when
// no axes converge at all (a sideways sweep with parallel axes), the median distance of the camera
// centres from their centroid (the capture's own extent) stands in.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <utility>
#include <vector>

#include "core/options.h"
#include "core/types.h"

namespace raytime {

// One image as pair selection sees it: plain pinhole geometry in the OpenCV pixel convention.
struct PairSelectionView {
  bool has_pose = false;  // false: no prior pose (or no focal length): window pairs only
  // world_from_cam: columns are the camera's x (right), y (down), z (optical axis) in the world.
  Eigen::Matrix3d world_from_cam_rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // camera centre in the world
  double fx = 0, fy = 0, cx = 0, cy = 0;             // pixels
  int width = 0, height = 0;                         // pixels
  // Position in capture order (the window's order): frame names in natural order, so a video's
  // "2.jpg" comes before "10.jpg" (Record3D names frames 0.jpg ... N.jpg without padding).
  int sequence = 0;
};

// Options of `matches` with `pairs: prior` (YAML keys = field names, flat in the matches stage).
struct PriorPairOptions {
  // Partners kept per image, the best by view overlap; the union over images is symmetric, so an
  // image may end up in more pairs. 10 gives every frame of a video or an orbit a few partners on
  // either side beyond its immediate neighbours (COLMAP's spatial matcher keeps 50 by distance).
  int prior_neighbors = 10;
  // Also pair each image with the next prior_window images in capture order (natural name
  // order: video frames), whatever their poses; 0 = none. Keeps consecutive frames matched where
  // the prior is wrong, and pairs images that have no prior pose.
  int prior_window = 0;
  // Largest viewpoint change, degrees: between the optical axes of a chosen pair, and where an
  // overlap sample's weight reaches 0. SIFT rarely matches beyond ~60° of viewpoint change; the
  // margin covers priors several degrees off.
  double prior_max_angle_deg = 75;
  // Smallest view overlap (above) of a chosen pair: below it, the cameras hardly see the same
  // scene even at the wrong depth.
  double prior_min_overlap = 0.05;
  // Largest resolution ratio between the two views of an overlap sample (SIFT's scale space
  // covers ~2 octaves of scale change in practice).
  double prior_max_scale_ratio = 4;
  // Scene depth along each optical axis in the prior's units; 0 = auto (above).
  double prior_scene_depth = 0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("prior_neighbors", prior_neighbors,
      "pairs: prior: partners per image, the best by view overlap under the prior (SPEC §5)",
      Positive(), AtMost(1e5));
    v("prior_window", prior_window,
      "pairs: prior: also pair each image with the next N in natural name order (video); 0 = none",
      NonNegative(), AtMost(1e5));
    v("prior_max_angle_deg", prior_max_angle_deg,
      "pairs: prior: largest viewpoint change of a pair (optical axes, rays to a point), degrees",
      Positive(), AtMost(180));
    v("prior_min_overlap", prior_min_overlap,
      "pairs: prior: smallest view overlap (frustum samples seen by both, viewpoint-weighted)",
      NonNegative(), Below(1));
    v("prior_max_scale_ratio", prior_max_scale_ratio,
      "pairs: prior: largest resolution ratio between two views of a scene point", AtLeast(1),
      AtMost(1000));
    v("prior_scene_depth", prior_scene_depth,
      "pairs: prior: scene depth along the optical axes in pose units; 0 = from the cameras",
      NonNegative(), AtMost(1e9));
  }
};

struct PairSelectionSummary {
  int num_images = 0;
  int num_images_with_pose = 0;
  int64_t num_exhaustive_pairs = 0;  // N (N - 1) / 2
  int64_t num_pairs = 0;             // chosen
  int64_t num_overlap_pairs = 0;     // chosen as one of an image's k best
  int64_t num_window_pairs = 0;      // chosen by the window only
  int min_partners = 0;              // per image, over images with a pose
  double median_partners = 0;
  int max_partners = 0;
  // Images with a pose that no pair touches (every other camera failed the gates).
  std::vector<int> unpaired_images;
  double median_scene_depth = 0;   // used, over images with a pose
  std::string scene_depth_source;  // "given", "axes" (auto), "extent" (auto fallback)
  double seconds = 0;

  nlohmann::json ToJson() const;  // the fields by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PairSelectionSummary, num_images, num_images_with_pose,
                                   num_exhaustive_pairs, num_pairs, num_overlap_pairs,
                                   num_window_pairs, min_partners, median_partners, max_partners,
                                   unpaired_images, median_scene_depth, scene_depth_source, seconds)

// Symmetric view overlap of two posed views in [0, 1] (see the top of this file), at the scene
// depths depth_a and depth_b along their optical axes.
double ViewOverlap(const PairSelectionView& a, double depth_a, const PairSelectionView& b,
                   double depth_b, double max_scale_ratio, double max_angle_deg);

// Scene depth per view (0 for views without a pose): `given` when positive, else auto (above).
// `source` (optional) receives "given", "axes" or "extent".
std::vector<double> SceneDepths(const std::vector<PairSelectionView>& views, double given,
                                std::string* source);

// The views of `images` under `poses` (world_from_cam by image name; images without one have
// has_pose false), with each image's pinhole intrinsics.
std::vector<PairSelectionView> PairSelectionViews(const ImageSet& images, const PoseSet& poses);

// The pairs (i < j, indices into `views`) to match: each posed image's prior_neighbors best
// partners by view overlap among those passing the gates, united symmetrically, plus the window.
// Sorted, without duplicates; deterministic (ties: nearer centre first, then lower index).
std::vector<std::pair<int, int>> SelectPriorPairs(const std::vector<PairSelectionView>& views,
                                                  const PriorPairOptions& options,
                                                  PairSelectionSummary* summary);

}  // namespace raytime
