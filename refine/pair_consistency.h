// Per image pair, how well the solved state explains its matches: the median over the pair's used
// matches of the symmetric cross-projection residual of paper eqs. (rij)/(rji), evaluated at the
// solved poses, intrinsics and ray times. The numeric kernel of the inconsistent-pairs guardrail
// (guardrails.h; beyond the paper, cf. its §4.11 "Failure analysis" on repeated structure). It
// recomputes every residual from plain arrays with the templated geometry of ray_geometry.h, the
// arithmetic the cost functors run, so it reads no solver state (no Ceres, no evaluation cache).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "refine/refine.h"

namespace raytime {

using IntrinsicsVector = Eigen::Matrix<double, kNumIntrinsics, 1>;  // fx fy cx cy k1 k2 p1 p2

// r = π_target(O_s + t R_s ray(û_source)) - û_target, px: the ray point of the source observation
// (distorted pixel `source_pixel` in the camera `source_world_from_cam`) at ray time `ray_time`,
// projected with the plain pinhole model into the target camera, minus the target observation's
// undistorted pixel. The value of CrossProjectionAutoDiffCost (and of the cached cost) at the same
// parameters; the rotations must be unit quaternions.
Eigen::Vector2d CrossProjectionResidual(const IntrinsicsVector& intrinsics,
                                        const Rigid3& source_world_from_cam, double ray_time,
                                        const Eigen::Vector2d& source_pixel,
                                        const Rigid3& target_world_from_cam,
                                        const Eigen::Vector2d& target_pixel);

// The used matches of one image pair, as rows of observation indices (image1's, image2's).
struct PairObservationMatches {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> observations;
};

// One PairResidual per entry of `pairs`, in order. Observation o is seen in image images(o) at the
// distorted pixel pixels.row(o); the point the solve holds for it is the ray point of observation
// point_source(o) at ray time point_ray_time(o) (o itself and its own ray time in the
// per-observation layout, its track's anchor and the track's ray time in the anchored one). A
// match (a, b) has two residuals, a's point in b's image against b and b's point in a's image
// against a; a residual whose point lies on a ray of the target's own image is skipped (the solve
// has no such residual; for the point's own observation it is identically zero), so an anchored
// match that contains its anchor keeps one. The match's value is the root mean square of its
// residual norms (px per direction); the pair's is the median over its matches (the mean of the
// two middle values for an even count). A non-finite residual counts as infinitely large.
std::vector<PairResidual> PairResidualMedians(
    const IntrinsicsVector& intrinsics, const std::vector<Rigid3>& world_from_cam,
    const Eigen::VectorXi& images, const Keypoints& pixels, const Eigen::VectorXi& point_source,
    const Eigen::VectorXd& point_ray_time, const std::vector<PairObservationMatches>& pairs);

}  // namespace raytime
