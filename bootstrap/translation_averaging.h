// Camera centres from pairwise translation directions: least unsquared deviations (LUD, Ozyesil &
// Singer, CVPR 2015) solved by iteratively reweighted least squares with one scale per edge
// (SPEC §4; paper §4.8 "Refinement without an external prior": "LUD-style iteratively reweighted
// least squares with per-edge scales").
#pragma once

#include <Eigen/Core>
#include <vector>
#include "core/options.h"

namespace raytime {

// Measured direction between the centres of nodes i and j, in the world frame of the averaged
// rotations: O_i - O_j = gamma * direction for an unknown gamma > 0.
struct RelativeDirection {
  int i = 0;
  int j = 0;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  // unit length
};

struct TranslationAveragingOptions {
  // LUD: minimize sum_ij |O_i - O_j - gamma_ij d_ij| subject to gamma_ij >= 1. Each reweighting
  // round solves the weighted least-squares problem with weights 1 / max(|r_ij|, lud_delta);
  // gamma_ij >= 1 fixes the scale and keeps the centres apart (paper §4.8: the seed must not put
  // all cameras at one point).
  int lud_iterations = 100;
  double lud_delta = 1e-6;         // weight floor, in the solution's units (edges have length >= 1)
  double lud_tolerance = 1e-7;     // stop when no centre moves by more than this (same units)
  int lud_newton_iterations = 50;  // inner solver iterations per round (semi-smooth Newton)

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("lud_iterations", lud_iterations, "LUD translation averaging: reweighting rounds", Positive(),
      AtMost(1e4));
    v("lud_delta", lud_delta, "LUD: weight floor, solution units (edges have length >= 1)",
      Positive(), AtMost(1e6));
    v("lud_tolerance", lud_tolerance, "LUD: stop when no centre moves more than this", Positive(),
      AtMost(1e6));
    v("lud_newton_iterations", lud_newton_iterations,
      "LUD: semi-smooth Newton iterations per round", Positive(), AtMost(1e4));
  }
};

struct TranslationAveragingResult {
  // Per node: camera centre. Only the largest connected component of the direction graph is
  // registered (its centroid at the origin); the other nodes keep zero.
  std::vector<Eigen::Vector3d> centres;
  std::vector<bool> registered;
  int num_registered = 0;
  int num_edges_used = 0;
  int iterations = 0;  // reweighting rounds performed
  bool converged = false;
  // Per input edge: angle between the measured direction and O_i - O_j (degrees) and the fitted
  // scale gamma_ij; NaN outside the component.
  std::vector<double> edge_residual_deg;
  std::vector<double> edge_scale;
  double mean_residual_deg = 0.0;
  double median_residual_deg = 0.0;
};

// Throws std::invalid_argument on a node index out of range, a self-loop or a direction that is
// not a finite non-zero vector.
TranslationAveragingResult AverageTranslations(int num_nodes,
                                               const std::vector<RelativeDirection>& edges,
                                               const TranslationAveragingOptions& options);

}  // namespace raytime
