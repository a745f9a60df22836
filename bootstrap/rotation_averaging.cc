#include "bootstrap/rotation_averaging.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <stdexcept>
#include <string>

#include "bootstrap/stats.h"
#include "bootstrap/view_graph.h"
#include "core/geometry.h"

namespace raytime {
namespace {

// Weight floor of the L1 stage: 1/|r| is capped at 1/kL1Floor so that edges the current
// estimate fits exactly (the spanning tree's) keep a finite weight.
constexpr double kL1FloorRad = 1e-6;

Eigen::Vector3d EdgeError(const RelativeRotation& e, const std::vector<Eigen::Matrix3d>& r) {
  // E = R_ji_measured (R_j^T R_i)^T: the identity when the estimate reproduces the measurement.
  return LogSO3(e.cam_j_from_cam_i * r[e.i].transpose() * r[e.j]);
}

// One IRLS step in the tangent space. With left updates R_i <- Exp(w_i) R_i, the edge error
// linearizes to R_j^T (w_i - w_j) = Log(E), so every edge contributes the same 3x3 identity
// blocks: the normal matrix is the weighted graph Laplacian (root removed) times I_3 and the
// three coordinates decouple into three solves with one sparse factorization.
double IrlsStep(const std::vector<RelativeRotation>& edges, const std::vector<int>& used,
                const std::vector<double>& weights, const std::vector<int>& variable,
                int num_variables, std::vector<Eigen::Matrix3d>* rotations) {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(used.size() * 4);
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(num_variables, 3);
  for (size_t k = 0; k < used.size(); ++k) {
    const RelativeRotation& e = edges[used[k]];
    const double w = weights[k];
    const Eigen::Vector3d b = (*rotations)[e.j] * EdgeError(e, *rotations);
    const int vi = variable[e.i], vj = variable[e.j];
    if (vi >= 0) {
      triplets.emplace_back(vi, vi, w);
      rhs.row(vi) += w * b.transpose();
    }
    if (vj >= 0) {
      triplets.emplace_back(vj, vj, w);
      rhs.row(vj) -= w * b.transpose();
    }
    if (vi >= 0 && vj >= 0) {
      triplets.emplace_back(vi, vj, -w);
      triplets.emplace_back(vj, vi, -w);
    }
  }
  Eigen::SparseMatrix<double> laplacian(num_variables, num_variables);
  laplacian.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(laplacian);
  if (solver.info() != Eigen::Success) {
    throw std::runtime_error("rotation averaging: the weighted Laplacian is not factorizable");
  }
  const Eigen::MatrixXd omega = solver.solve(rhs);
  double max_step = 0.0;
  for (size_t node = 0; node < variable.size(); ++node) {
    if (variable[node] < 0) continue;
    const Eigen::Vector3d w = omega.row(variable[node]).transpose();
    (*rotations)[node] = Orthonormalize(ExpSO3(w) * (*rotations)[node]);
    max_step = std::max(max_step, w.norm());
  }
  return max_step;
}

}  // namespace

void ValidateRotationAveragingOptions(const RotationAveragingOptions& options) {
  if (options.l1_iterations < 0 || options.irls_iterations < 0) {
    throw std::invalid_argument("rotation averaging: iteration counts must be >= 0");
  }
  if (!(options.robust_scale_deg > 0)) {
    throw std::invalid_argument("rotation averaging: robust_scale_deg must be > 0");
  }
  if (!(options.rotation_tolerance_deg > 0)) {
    throw std::invalid_argument("rotation averaging: rotation_tolerance_deg must be > 0");
  }
}

RotationAveragingResult AverageRotations(int num_nodes, const std::vector<RelativeRotation>& edges,
                                         const RotationAveragingOptions& options) {
  ValidateRotationAveragingOptions(options);
  if (num_nodes < 0) throw std::invalid_argument("AverageRotations: negative node count");
  std::vector<std::pair<int, int>> pairs;
  for (const auto& e : edges) {
    if (e.i < 0 || e.j < 0 || e.i >= num_nodes || e.j >= num_nodes || e.i == e.j) {
      throw std::invalid_argument("AverageRotations: bad edge (" + std::to_string(e.i) + ", " +
                                  std::to_string(e.j) + ") for " + std::to_string(num_nodes) +
                                  " nodes");
    }
    if (!e.cam_j_from_cam_i.allFinite() || !(e.weight > 0)) {
      throw std::invalid_argument("AverageRotations: edge (" + std::to_string(e.i) + ", " +
                                  std::to_string(e.j) +
                                  ") has a non-finite rotation or a non-positive weight");
    }
    pairs.emplace_back(e.i, e.j);
  }

  RotationAveragingResult result;
  result.world_from_cam.assign(num_nodes, Eigen::Matrix3d::Identity());
  result.registered.assign(num_nodes, false);
  result.edge_residual_deg.assign(edges.size(), std::numeric_limits<double>::quiet_NaN());
  if (num_nodes == 0) return result;

  // Largest connected component: the only part with a common frame.
  const std::vector<int> labels = ConnectedComponents(num_nodes, pairs);
  std::vector<int> used;
  for (size_t k = 0; k < edges.size(); ++k) {
    if (labels[edges[k].i] == 0) used.push_back(static_cast<int>(k));
  }
  std::vector<double> strength(num_nodes, 0.0);
  for (int k : used) {
    strength[edges[k].i] += edges[k].weight;
    strength[edges[k].j] += edges[k].weight;
  }
  int root = -1;
  for (int node = 0; node < num_nodes; ++node) {
    if (labels[node] == 0 && (root < 0 || strength[node] > strength[root])) root = node;
  }
  result.root = root;
  for (int node = 0; node < num_nodes; ++node) result.registered[node] = labels[node] == 0;
  result.num_registered =
      static_cast<int>(std::count(result.registered.begin(), result.registered.end(), true));
  result.num_edges_used = static_cast<int>(used.size());
  if (used.empty()) {
    result.converged = true;
    return result;
  }

  // Maximum-spanning-tree initialization weighted by inlier counts (paper §4.8): the most
  // supported pairs define the first estimate, propagated breadth-first from the root.
  std::vector<std::pair<int, int>> used_pairs;
  std::vector<double> used_weights;
  for (int k : used) {
    used_pairs.emplace_back(edges[k].i, edges[k].j);
    used_weights.push_back(edges[k].weight);
  }
  std::vector<std::vector<int>> tree(num_nodes);
  for (int t : MaximumSpanningForest(num_nodes, used_pairs, used_weights)) {
    tree[edges[used[t]].i].push_back(used[t]);
    tree[edges[used[t]].j].push_back(used[t]);
  }
  std::vector<bool> placed(num_nodes, false);
  std::queue<int> frontier;
  placed[root] = true;
  frontier.push(root);
  while (!frontier.empty()) {
    const int node = frontier.front();
    frontier.pop();
    for (int k : tree[node]) {
      const RelativeRotation& e = edges[k];
      const int other = e.i == node ? e.j : e.i;
      if (placed[other]) continue;
      // R_ji = R_j^T R_i  =>  R_j = R_i R_ji^T  and  R_i = R_j R_ji.
      const Eigen::Matrix3d& known = result.world_from_cam[node];
      result.world_from_cam[other] = e.i == node
                                         ? Eigen::Matrix3d(known * e.cam_j_from_cam_i.transpose())
                                         : Eigen::Matrix3d(known * e.cam_j_from_cam_i);
      placed[other] = true;
      frontier.push(other);
    }
  }

  std::vector<int> variable(num_nodes, -1);
  int num_variables = 0;
  for (int node = 0; node < num_nodes; ++node) {
    if (result.registered[node] && node != root) variable[node] = num_variables++;
  }
  const double tolerance = RadiansFromDegrees(options.rotation_tolerance_deg);
  const double sigma = RadiansFromDegrees(options.robust_scale_deg);
  std::vector<double> weights(used.size());
  bool l1_converged = options.l1_iterations == 0;
  bool irls_converged = options.irls_iterations == 0;
  if (num_variables > 0) {
    for (int it = 0; it < options.l1_iterations; ++it) {
      for (size_t k = 0; k < used.size(); ++k) {
        const double r = EdgeError(edges[used[k]], result.world_from_cam).norm();
        weights[k] = 1.0 / std::max(r, kL1FloorRad);
      }
      ++result.l1_iterations;
      if (IrlsStep(edges, used, weights, variable, num_variables, &result.world_from_cam) <
          tolerance) {
        l1_converged = true;
        break;
      }
    }
    for (int it = 0; it < options.irls_iterations; ++it) {
      // Geman-McClure: rho(r) = r^2 s^2 / (r^2 + s^2), IRLS weight s^4 / (r^2 + s^2)^2 (scaled
      // to 1 at r = 0 so the normal matrix stays well conditioned).
      for (size_t k = 0; k < used.size(); ++k) {
        const double r2 = EdgeError(edges[used[k]], result.world_from_cam).squaredNorm();
        const double s2 = sigma * sigma;
        weights[k] = std::max(s2 * s2 / ((r2 + s2) * (r2 + s2)), 1e-12);
      }
      ++result.irls_iterations;
      if (IrlsStep(edges, used, weights, variable, num_variables, &result.world_from_cam) <
          tolerance) {
        irls_converged = true;
        break;
      }
    }
  } else {
    l1_converged = irls_converged = true;
  }
  result.converged = options.irls_iterations > 0 ? irls_converged : l1_converged;

  std::vector<double> residuals;
  for (int k : used) {
    const double r = DegreesFromRadians(EdgeError(edges[k], result.world_from_cam).norm());
    result.edge_residual_deg[k] = r;
    residuals.push_back(r);
  }
  result.mean_residual_deg = FiniteMean(residuals);
  result.median_residual_deg = FiniteMedian(residuals);
  return result;
}

}  // namespace raytime
