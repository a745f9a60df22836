// Which observations, ray times and cross-projection residuals a problem holds (paper §3.2, §3.6):
// the combinatorial half of the problem builder, kept free of Ceres so it tests on plain data.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "refine/refine_types.h"
#include "refine/solve/camera_blocks.h"

namespace raytime {

// Observation (camera `image`, keypoint `keypoint`) appearing in at least one used match.
struct LayoutObservation {
  int image = 0;
  int keypoint = 0;
  int ray_time = -1;  // index of the ray time living on this observation's ray, -1 if none
};

// A used match: its pair in RefineInput::pairs and its two observations (image1's, image2's).
struct LayoutMatch {
  int pair = 0;
  int observation1 = 0;
  int observation2 = 0;
};

// r = π_target_image(X_source) - û_target: projects the source observation's ray point into the
// target observation's camera (paper eqs. rij, rji).
struct CrossProjection {
  int source = 0;  // observation index (owns a ray time)
  int target = 0;  // observation index, in another image
};

struct ProblemLayout {
  std::vector<LayoutObservation> observations;  // sorted by (image, keypoint)
  std::vector<int> ray_time_observation;        // per ray time: the observation it lives on
  std::vector<CrossProjection> residuals;
  std::vector<LayoutMatch> matches;  // the used matches, in input order
  int num_matches_input = 0;         // between distinct images
  int num_matches_used = 0;          // after the cap
  int num_tracks = 0;                // anchored only
};

// Deterministic per-pair subset (§4.7 "match capping"): indices of at most `cap` of `count`
// matches, uniform without replacement, sorted, from a seed mixing `seed` with the pair's image
// indices; all indices when cap is 0 or >= count. The generator is written out (splitmix64 and a
// partial Fisher–Yates shuffle) so a seed names the same subset with any standard library.
std::vector<int> CappedMatchIndices(int image1, int image2, int count, int cap, int seed);

// Per-observation layout (§3.2): every observation of a used match owns one ray time, and each
// match gives the two symmetric residuals. Matches within one image are skipped (Ceres aborts
// on a residual holding the same pose block twice). Throws InputError on an image or keypoint
// index out of range.
ProblemLayout BuildPerObservationLayout(const RefineInput& input, int max_matches_per_pair,
                                        int seed);

// Anchored-track layout (§3.6): union-find tracks over the used matches; each track owns one
// ray time on its anchor (its first observation in (image, keypoint) order), and the anchor's
// ray point is projected into every other observation of the track in another image.
ProblemLayout BuildAnchoredLayout(const RefineInput& input, int max_matches_per_pair, int seed);

// Per image: whether some residual of the layout reaches it (the solvers hold the others at their
// start: their only term is the prior, whose minimum is the anchor).
std::vector<bool> ObservedImages(const ProblemLayout& layout, int num_images);

// With every intrinsic held, each observation's undistorted pixel and unit ray in its camera frame
// are constants of the solve (§3.2): computed once here, with the image's intrinsics block, by the
// arithmetic of the evaluation cache's value pass (UndistortPixel, PixelToUnitRay).
struct ObservationRays {
  std::vector<Eigen::Vector2d> undistorted;  // per layout observation
  std::vector<Eigen::Vector3d> rays;
};
ObservationRays FixedObservationRays(const RefineInput& input, const ProblemLayout& layout,
                                     const CameraBlocks& cameras);

}  // namespace raytime
