// Global rotations from pairwise relative rotations (SPEC §4; paper §4.8 "Refinement without an
// external prior": "a maximum-spanning-tree initial guess, then iteratively reweighted
// least-squares averaging in the tangent space", after Chatterjee & Govindu, ICCV 2013).
#pragma once

#include <Eigen/Core>
#include <vector>
#include "core/options.h"

namespace raytime {

// One measured relative rotation between nodes i and j. With world_from_cam rotations R (camera
// to world), the measurement is cam_j_from_cam_i = R_j^T R_i.
struct RelativeRotation {
  int i = 0;
  int j = 0;
  Eigen::Matrix3d cam_j_from_cam_i = Eigen::Matrix3d::Identity();
  double weight = 1.0;  // spanning-tree weight (the pair's inlier count), > 0
};

struct RotationAveragingOptions {
  // Chatterjee & Govindu's two stages: L1 averaging, which needs no outlier scale and escapes a
  // spanning tree that contains wrong pairs (each of its `l1_iterations` solves the convex L1
  // problem of one linearization by inner IRLS), then IRLS with the Geman-McClure loss at
  // `robust_scale_deg` (their σ = 5°), which sharpens the solution on the inliers.
  int l1_iterations = 20;
  int irls_iterations = 30;
  double robust_scale_deg = 5.0;  // degrees
  // A stage (and an L1 step's inner IRLS) stops when the largest tangent-space update is below
  // this, degrees.
  double rotation_tolerance_deg = 1e-5;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("l1_iterations", l1_iterations, "Rotation averaging: L1 linearizations (Chatterjee-Govindu)",
      NonNegative(), AtMost(1e4));
    v("irls_iterations", irls_iterations, "Rotation averaging: Geman-McClure IRLS iterations",
      NonNegative(), AtMost(1e4));
    v("robust_scale_deg", robust_scale_deg, "Rotation averaging: Geman-McClure scale σ, degrees",
      Positive(), AtMost(180));
    v("rotation_tolerance_deg", rotation_tolerance_deg,
      "Rotation averaging: stop below this largest update, degrees", Positive(), AtMost(180));
  }
};

struct RotationAveragingResult {
  // Per node: camera-to-world rotation R_i. Only nodes of the largest connected component are
  // registered; the others keep the identity. Gauge: the best-connected node (largest weight sum)
  // has the identity.
  std::vector<Eigen::Matrix3d> world_from_cam;
  std::vector<bool> registered;
  int root = -1;
  int num_registered = 0;
  int num_edges_used = 0;  // edges inside the component
  int l1_iterations = 0;   // performed
  int irls_iterations = 0;
  bool converged = false;
  // Per input edge: angle of R_ji_measured^T R_j^T R_i in degrees (NaN outside the component).
  std::vector<double> edge_residual_deg;
  double mean_residual_deg = 0.0;  // over the component's edges
  double median_residual_deg = 0.0;
};

// Throws std::invalid_argument on a node index out of range, a self-loop, a non-finite rotation
// or a non-positive weight.
RotationAveragingResult AverageRotations(int num_nodes, const std::vector<RelativeRotation>& edges,
                                         const RotationAveragingOptions& options);

}  // namespace raytime
