// A bundle adjustment with one 3D point per track (issue 50): the maximum-likelihood estimator
// under independent keypoint noise, which the ray-time problem approaches but is not (one depth
// per observation, two cross-projection residuals per match, each carrying two keypoints' noise;
// docs/efficiency.md). The recipe's track finish (refine/recipes/track_finish.h) runs it from the
// ray-time solution on the tracks that solution explains; here it is only the minimisation:
// r = π_i(X_k) − û_ik for every observation of a track (the pinhole on undistorted pixels, as in
// every residual of the solve), as a mean of squares over observations, plus the same pose prior
// terms as a pass (λp/N, λR/N, §3.3). Plain least squares: the caller chooses the observations
// (the robust part: which matches the ray-time solution explains, and a rejection round on the
// points' own residuals). Under a robust loss Ceres' LM converges only linearly here: the
// reweighted model overstates the curvature of every down-weighted residual, so each step goes
// about half the way.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/geometry.h"

namespace raytime {

struct TrackAdjustmentProblem {
  // Per image: the pose (the start; the solution after AdjustTracks), the pinhole (fx, fy, cx, cy)
  // of its intrinsics, and its prior terms' anchor.
  std::vector<Rigid3> world_from_cam;
  std::vector<Eigen::Vector4d> pinhole;
  std::vector<Rigid3> anchor;
  // Per track, its point (the start; the solution after).
  std::vector<Eigen::Vector3d> points;
  // Per observation: its track, its image and its undistorted pixel. Every track has observations
  // in at least two images, at most one per image.
  std::vector<int> observation_track;
  std::vector<int> observation_image;
  std::vector<Eigen::Vector2d> observation_pixel;
  double position_weight = 0.0;     // λp (per image: / N, as a pass's prior terms)
  double orientation_weight = 0.0;  // λR
};

struct TrackAdjustmentSummary {
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  bool converged = false;  // Ceres' convergence (not a failure or the iteration limit)
  std::string message;     // Ceres' termination message
};

// Adjusts poses and points of `problem` in place. Images without observations are held. The match
// term does not see a global similarity and the prior terms curve it some 1e-7 as much, so Ceres'
// LM crept along it for hundreds of iterations: the gauge is held instead (the most observed
// camera, one centre coordinate of the camera farthest from it) and the caller's gauge polish
// places the solution as every pass's (refine/solve/gauge_polish.h). One
// thread: Ceres' Schur elimination sums the points' shares into the reduced camera matrix in
// thread order, and the refine's results are the same bits on any thread count.
TrackAdjustmentSummary AdjustTracks(TrackAdjustmentProblem* problem);

// Each point alone by Gauss–Newton at the current poses (`iterations` steps, a point whose step
// fails to solve kept): the adjustment's structure without its cost, so that residuals judged here
// are close to those at its solution.
void AdjustPointsAtFixedPoses(TrackAdjustmentProblem* problem, int iterations);

// The residual of observation o at the problem's current poses and points, px.
Eigen::Vector2d TrackResidual(const TrackAdjustmentProblem& problem, int observation);

// ∂r/∂(φ, δO) of observation o in the local parameters of its pose (R ← Exp(φ)·R, O ← O + δO, as
// the ray-time LM's) and ∂r/∂X in its point, at the current state; returns the residual
// (TrackResidual's value).
Eigen::Vector2d TrackResidualJacobians(const TrackAdjustmentProblem& problem, int observation,
                                       Eigen::Matrix<double, 2, 6>* pose_jacobian,
                                       Eigen::Matrix<double, 2, 3>* point_jacobian);

}  // namespace raytime
