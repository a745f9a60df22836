// The ray-time LM's retraction (ray_time_lm_solver.h): how a step of the linearized problem moves
// the poses and the ray times. A pose steps in its local parameters (φ, δO), R ← Exp(φ)·R and
// O ← O + δO, except for the step's global similarity part, which is applied as a similarity;
// a ray time steps in inverse depth.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/geometry.h"

namespace raytime {

// [v]×, the matrix of the cross product v × ·.
Eigen::Matrix3d CrossMatrix(const Eigen::Vector3d& v);

// A camera's step (rotation φ, then centre) under an infinitesimal global similarity g = (ω, λ,
// τ) about a pivot, o the centre relative to it: φ = ω, δO = ω × o + λ·o + τ.
Eigen::Matrix<double, 6, 7> SimilarityTangent(const Eigen::Vector3d& o);

// The centroid of the cameras in the step (variable[i] >= 0): the similarity's pivot, so that a
// prior in far coordinates (a GPS prior's UTM metres) neither conditions the fit badly nor turns
// the cameras on arcs about a distant origin.
Eigen::Vector3d SimilarityPivot(const std::vector<Rigid3>& poses, const std::vector<int>& variable);

// The similarity part (about SimilarityPivot) of a step of the cameras (6 per camera, at
// 6·variable[i]; variable[i] < 0: not in the step): least squares over SimilarityTangent.
Eigen::Matrix<double, 7, 1> SimilarityPart(const std::vector<Rigid3>& poses,
                                           const std::vector<int>& variable,
                                           const Eigen::VectorXd& step);

// poses ⊕ step with the step's similarity part applied as a similarity: the rest taken as before
// (rotation by its exponential, centre added), then R ← Exp(ω)·R, O ← p + e^λ·Exp(ω)·(O - p) + τ
// with p the poses' SimilarityPivot. To first order this is the plain update; along the 7
// directions no match sees it is exact. Why: the match term is invariant under a global
// similarity (the ray times scaled with it), so along it only the weak prior terms curve the
// cost, and a linear step along it bends the shape by its second order, which the matches pull
// back: the solve crept along the similarity in many short steps, nearly all similarity
// (measured: docs/scaling.md, "Measurements behind the LM's choices").
void RetractPoses(const std::vector<int>& variable, const Eigen::VectorXd& step,
                  const Eigen::Matrix<double, 7, 1>& similarity, std::vector<Rigid3>* poses);

// The ray time after a step δ of the linearized problem: t ← t / (1 - δ/t), the step taken in
// inverse depth (1/t ← 1/t - δ/t², the same first-order move), at most kMaxRayTimeGrowth times
// further per step and never below kRayTimeLowerBound. Why: a point's projection is nearly linear
// in its inverse depth and far from linear in its depth once the point is far, so t + δ
// overshoots far points, whose steps of millions then dominate and get steps rejected
// (measured: docs/scaling.md, "Measurements behind the LM's choices"). A step toward the camera
// shrinks t by a factor and cannot cross it.
double RetractRayTime(double ray_time, double step);
inline constexpr double kMaxRayTimeGrowth = 10.0;

}  // namespace raytime
