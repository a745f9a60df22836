// The track finish (RefineOptions::track_finish, issue 50): the ray-time problem is close to, but
// not, the maximum-likelihood estimator under keypoint noise (one depth per observation, two
// cross-projection residuals per match carrying two keypoints' noise, tracks as pairwise terms);
// a bundle adjustment with one point per track is that estimator (docs/efficiency.md measures
// both against the Cramér–Rao bound). Once the ray-time solve has placed every frame, its solution
// decides which matches are right, and the bundle adjustment on them adds the efficiency:
//
//   1. Inliers: the last pass's used matches both of whose cross-projection residuals, at its
//      solution, lie where its arctan loss still weighs them (|r|² ≤ 2a: weight ≥ 1/5).
//   2. Tracks: their union-find components; one with two keypoints in one image holds a wrong
//      match and is left out whole.
//   3. Points: each track's observations' ray points averaged (the ray-time structure, no new
//      triangulation from the prior); a point behind one of its cameras leaves its track out.
//   4. Rejection: each point adjusted alone at the ray-time poses, the observations it leaves
//      above 4 σ (σ from their median) go, and a track left with one observation. The noise the
//      rest implies is tested already here (as in 6), before the adjustment's cost.
//   5. The adjustment (refine/solve/track_adjustment.h, plain least squares on what is left) with
//      the last pass's prior terms, then the same gauge polish.
//   6. The check: converged, every frame within track_finish_max_move_sigma of its ray-time σ (the
//      two estimators differ by less than either's spread when both are right), and the
//      residuals implying the same keypoint noise as the ray-time solve's (within
//      kTrackFinishMaxNoiseRatio): wrong tracks raise it. A finish that fails is not returned;
//      the summary says which test and by how much.
//
// On acceptance the state holds its poses, each track's observations their ray times at its point
// (the depth of the point along the ray) and the uncertainty is the adjustment's.
#pragma once

#include <vector>

#include "core/geometry.h"
#include "refine/checks/pose_uncertainty.h"
#include "refine/recipes/refine_pass.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"

namespace raytime {

// The residuals' keypoint noise may rise this much over the ray-time solve's before the finish is
// rejected: both estimate the same σ when the tracks are right, but the ray-time estimate weighs
// residuals by the arctan loss and reads low when wrong matches are many (docs/efficiency.md).
inline constexpr double kTrackFinishMaxNoiseRatio = 1.5;

// Runs the finish from *state (the last pass's solution of `input`, `last` its summary) when
// options.track_finish; `uncertainty` is the ray-time solve's (its σ per frame is the check's
// yardstick; replaced by the adjustment's when accepted).
TrackFinishSummary FinishOnTracks(const RefineInput& input, const RefineOptions& options,
                                  const RefinePassSummary& last, PassState* state,
                                  PoseUncertaintySummary* uncertainty);

}  // namespace raytime
