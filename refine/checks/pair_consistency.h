// Per image pair, whether the solved poses and intrinsics explain its matches: the median over the
// pair's used matches of a symmetric epipolar distance restricted to positive ray times. The
// numeric kernel of the inconsistent-pairs guardrail (guardrails.h; beyond the paper, cf. its
// §4.11 "Failure analysis" on repeated structure). It reads no ray times: from far-off priors some
// of them end where the arctan loss has no gradient, and the cross-projection residual at such a
// stuck ray time says nothing about the poses (hundreds of pixels on a correct pair whose epipolar
// error is a fraction of a pixel). It reads no solver state either (no Ceres, no evaluation cache).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "refine/refine_types.h"

namespace raytime {

using IntrinsicsVector = Eigen::Matrix<double, kNumIntrinsics, 1>;  // fx fy cx cy k1 k2 p1 p2

// min over t > 0 of |π_target(O_s + t R_s ray(û_source)) - û_target|, px: the smallest
// cross-projection residual of paper eqs. (rij)/(rji) (CrossProjectionResidual, the plain
// pinhole π of ray_geometry.h) that the source observation (distorted pixel `source_pixel` in the
// camera `source_world_from_cam` with `source_intrinsics`) can reach against the target
// observation (its camera's intrinsics `target_intrinsics`, the same as the source's when the
// images share a camera) with a free ray time, i.e. the best the solve could do for this residual
// at these poses and intrinsics whatever its ray time. Geometrically: the distance from the
// target's undistorted pixel to the image of the source ray's positive half-line, a part of the
// epipolar line bounded by the epipole (t → 0) and the ray's vanishing point (t → ∞). When the
// half-line stays on one side of the target camera's focal plane that part is the segment between
// the two; when it crosses the plane, its image runs through infinity and is the line minus that
// segment. Either way the distance is the one to the epipolar line where the foot of the
// perpendicular lies on the image, and the distance to the nearer end point otherwise (an infimum:
// the end points are limits). Like the cost functor, π divides by the depth whatever its sign, so a
// point behind the target camera counts at its central projection. +inf when every point of the
// half-line lies in the target's focal plane; the rotations must be unit quaternions.
double PositiveRayEpipolarDistance(const IntrinsicsVector& source_intrinsics,
                                   const Rigid3& source_world_from_cam,
                                   const Eigen::Vector2d& source_pixel,
                                   const IntrinsicsVector& target_intrinsics,
                                   const Rigid3& target_world_from_cam,
                                   const Eigen::Vector2d& target_pixel);

// The used matches of one image pair, as rows of observation indices (image1's, image2's).
struct PairObservationMatches {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> observations;
};

// One PairResidual per entry of `pairs`, in order. Observation o is seen in image images(o) at the
// distorted pixel pixels.row(o); the two observations of a match lie in different images. Image i
// has the pose world_from_cam[i] and the intrinsics image_intrinsics[i]. A match
// (a, b) has two values, PositiveRayEpipolarDistance from a into b's image and from b into a's
// (whatever ray the solve's layout puts the point on: the test is about the relative pose of the
// pair's two cameras); the match's value is their root mean square, the pair's the median over its
// matches (the mean of the two middle values for an even count). A non-finite value counts as
// infinitely large.
std::vector<PairResidual> PairResidualMedians(const std::vector<IntrinsicsVector>& image_intrinsics,
                                              const std::vector<Rigid3>& world_from_cam,
                                              const Eigen::VectorXi& images,
                                              const Keypoints& pixels,
                                              const std::vector<PairObservationMatches>& pairs);

}  // namespace raytime
