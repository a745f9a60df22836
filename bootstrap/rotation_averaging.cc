#include "bootstrap/rotation_averaging.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <stdexcept>
#include <string>

#include "bootstrap/view_graph.h"
#include "core/geometry.h"
#include "core/statistics.h"

namespace raytime {
namespace {

// Inner IRLS iterations of one L1 step and the floor of its weights 1/|r|: the linearized L1
// problem is convex, so its IRLS starts from the least-squares solution and needs only the floor
// to keep the weights of exactly fitted edges finite.
constexpr int kL1InnerIterations = 25;
constexpr double kL1FloorRad = 1e-7;

Eigen::Vector3d EdgeError(const RelativeRotation& e, const std::vector<Eigen::Matrix3d>& r) {
  // E = R_ji_measured (R_j^T R_i)^T: the identity when the estimate reproduces the measurement.
  return LogSO3(e.cam_j_from_cam_i * r[e.i].transpose() * r[e.j]);
}

// The tangent-space problem at the current rotations. With left updates R_i <- Exp(w_i) R_i the
// edge error linearizes to w_i - w_j = R_j Log(E) =: b_k, so every edge contributes identity
// blocks: the normal matrix is the weighted graph Laplacian (root removed) times I_3 and the
// three coordinates decouple into three solves sharing one sparse factorization.
class Linearization {
 public:
  Linearization(const std::vector<RelativeRotation>& edges, const std::vector<int>& used,
                const std::vector<int>& variable, int num_variables,
                const std::vector<Eigen::Matrix3d>& rotations)
      : edges_(edges), used_(used), variable_(variable), n_(num_variables) {
    for (int k : used) b_.push_back(rotations[edges[k].j] * EdgeError(edges[k], rotations));
  }

  // argmin over w of sum_k weight_k |w_i - w_j - b_k|^2, one row per variable.
  Eigen::MatrixXd Solve(const std::vector<double>& weights) const {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(used_.size() * 4);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n_, 3);
    for (size_t k = 0; k < used_.size(); ++k) {
      const RelativeRotation& e = edges_[used_[k]];
      const double w = weights[k];
      const int vi = variable_[e.i], vj = variable_[e.j];
      if (vi >= 0) {
        triplets.emplace_back(vi, vi, w);
        rhs.row(vi) += w * b_[k].transpose();
      }
      if (vj >= 0) {
        triplets.emplace_back(vj, vj, w);
        rhs.row(vj) -= w * b_[k].transpose();
      }
      if (vi >= 0 && vj >= 0) {
        triplets.emplace_back(vi, vj, -w);
        triplets.emplace_back(vj, vi, -w);
      }
    }
    Eigen::SparseMatrix<double> laplacian(n_, n_);
    laplacian.setFromTriplets(triplets.begin(), triplets.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(laplacian);
    if (solver.info() != Eigen::Success) {
      throw std::runtime_error("rotation averaging: the weighted Laplacian is not factorizable");
    }
    return solver.solve(rhs);
  }

  // |w_i - w_j - b_k| of every edge.
  std::vector<double> Residuals(const Eigen::MatrixXd& omega) const {
    std::vector<double> r(used_.size());
    for (size_t k = 0; k < used_.size(); ++k) {
      const RelativeRotation& e = edges_[used_[k]];
      r[k] = (Row(omega, e.i) - Row(omega, e.j) - b_[k]).norm();
    }
    return r;
  }

  // Applies R_i <- Exp(w_i) R_i; returns the largest |w_i|.
  double Apply(const Eigen::MatrixXd& omega, std::vector<Eigen::Matrix3d>* rotations) const {
    double max_step = 0.0;
    for (size_t node = 0; node < variable_.size(); ++node) {
      if (variable_[node] < 0) continue;
      const Eigen::Vector3d w = Row(omega, static_cast<int>(node));
      (*rotations)[node] = Orthonormalize(ExpSO3(w) * (*rotations)[node]);
      max_step = std::max(max_step, w.norm());
    }
    return max_step;
  }

 private:
  Eigen::Vector3d Row(const Eigen::MatrixXd& omega, int node) const {
    return variable_[node] < 0 ? Eigen::Vector3d::Zero()
                               : Eigen::Vector3d(omega.row(variable_[node]).transpose());
  }

  const std::vector<RelativeRotation>& edges_;
  const std::vector<int>& used_;
  const std::vector<int>& variable_;
  const int n_;
  std::vector<Eigen::Vector3d> b_;
};

// Throws std::invalid_argument on an edge outside [0, num_nodes), a self-edge, a non-finite
// rotation or a non-positive weight.
void CheckEdges(int num_nodes, const std::vector<RelativeRotation>& edges) {
  if (num_nodes < 0) throw std::invalid_argument("AverageRotations: negative node count");
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
  }
}

// The largest connected component, the only part with a common frame: marks its nodes registered,
// picks as root its node of largest summed edge weight, and returns its edges.
std::vector<int> LargestComponent(int num_nodes, const std::vector<RelativeRotation>& edges,
                                  RotationAveragingResult* result) {
  std::vector<std::pair<int, int>> pairs;
  for (const auto& e : edges) pairs.emplace_back(e.i, e.j);
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
  result->root = root;
  for (int node = 0; node < num_nodes; ++node) result->registered[node] = labels[node] == 0;
  result->num_registered =
      static_cast<int>(std::count(result->registered.begin(), result->registered.end(), true));
  result->num_edges_used = static_cast<int>(used.size());
  return used;
}

// Maximum-spanning-tree initialization weighted by inlier counts (paper §4.8): the most supported
// pairs define the first estimate, propagated breadth-first from the root.
void SpanningTreeStart(int num_nodes, const std::vector<RelativeRotation>& edges,
                       const std::vector<int>& used, int root,
                       std::vector<Eigen::Matrix3d>* world_from_cam) {
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
      const Eigen::Matrix3d& known = (*world_from_cam)[node];
      (*world_from_cam)[other] = e.i == node
                                     ? Eigen::Matrix3d(known * e.cam_j_from_cam_i.transpose())
                                     : Eigen::Matrix3d(known * e.cam_j_from_cam_i);
      placed[other] = true;
      frontier.push(other);
    }
  }
}

// The edges and the variables the refinement steps share: every registered node but the root.
struct Refinement {
  const std::vector<RelativeRotation>& edges;
  const std::vector<int>& used;
  std::vector<int> variable;
  int num_variables = 0;
  double tolerance = 0.0;  // radians
};

// Up to `iterations` L1 steps: each the convex problem min sum_k |w_i - w_j - b_k| on the current
// linearization, solved by IRLS from its least-squares solution. True when a step fell below the
// tolerance.
bool L1Steps(const Refinement& problem, int iterations, RotationAveragingResult* result) {
  std::vector<double> weights(problem.used.size());
  for (int it = 0; it < iterations; ++it) {
    const Linearization linear(problem.edges, problem.used, problem.variable, problem.num_variables,
                               result->world_from_cam);
    std::fill(weights.begin(), weights.end(), 1.0);
    Eigen::MatrixXd omega = linear.Solve(weights);
    for (int inner = 0; inner < kL1InnerIterations; ++inner) {
      const std::vector<double> r = linear.Residuals(omega);
      for (size_t k = 0; k < problem.used.size(); ++k) {
        weights[k] = 1.0 / std::max(r[k], kL1FloorRad);
      }
      const Eigen::MatrixXd next = linear.Solve(weights);
      const double change = (next - omega).cwiseAbs().maxCoeff();
      omega = next;
      if (change < problem.tolerance) break;
    }
    ++result->l1_iterations;
    if (linear.Apply(omega, &result->world_from_cam) < problem.tolerance) return true;
  }
  return iterations == 0;
}

// Up to `iterations` Geman-McClure IRLS steps: rho(r) = r^2 s^2 / (r^2 + s^2), weight
// s^4 / (r^2 + s^2)^2 (scaled to 1 at r = 0 so the normal matrix stays well conditioned). True when
// a step fell below the tolerance.
bool IrlsSteps(const Refinement& problem, int iterations, double sigma,
               RotationAveragingResult* result) {
  std::vector<double> weights(problem.used.size());
  for (int it = 0; it < iterations; ++it) {
    for (size_t k = 0; k < problem.used.size(); ++k) {
      const double r2 =
          EdgeError(problem.edges[problem.used[k]], result->world_from_cam).squaredNorm();
      const double s2 = sigma * sigma;
      weights[k] = std::max(s2 * s2 / ((r2 + s2) * (r2 + s2)), 1e-12);
    }
    ++result->irls_iterations;
    const Linearization linear(problem.edges, problem.used, problem.variable, problem.num_variables,
                               result->world_from_cam);
    if (linear.Apply(linear.Solve(weights), &result->world_from_cam) < problem.tolerance) {
      return true;
    }
  }
  return iterations == 0;
}

// Every used edge's residual at the solution, with their mean and median.
void MeasureResiduals(const std::vector<RelativeRotation>& edges, const std::vector<int>& used,
                      RotationAveragingResult* result) {
  std::vector<double> residuals;
  for (int k : used) {
    const double r = DegreesFromRadians(EdgeError(edges[k], result->world_from_cam).norm());
    result->edge_residual_deg[k] = r;
    residuals.push_back(r);
  }
  result->mean_residual_deg = FiniteMean(residuals);
  result->median_residual_deg = FiniteUpperMedian(residuals);
}

}  // namespace

RotationAveragingResult AverageRotations(int num_nodes, const std::vector<RelativeRotation>& edges,
                                         const RotationAveragingOptions& options) {
  ValidateOptions(options, "rotation averaging");
  CheckEdges(num_nodes, edges);
  RotationAveragingResult result;
  result.world_from_cam.assign(num_nodes, Eigen::Matrix3d::Identity());
  result.registered.assign(num_nodes, false);
  result.edge_residual_deg.assign(edges.size(), std::numeric_limits<double>::quiet_NaN());
  if (num_nodes == 0) return result;

  // 1. The largest connected component and its root.
  const std::vector<int> used = LargestComponent(num_nodes, edges, &result);
  if (used.empty()) {
    result.converged = true;
    return result;
  }
  // 2. The first estimate from the maximum spanning tree.
  SpanningTreeStart(num_nodes, edges, used, result.root, &result.world_from_cam);

  // 3. L1 steps, then robust IRLS steps, on every registered node but the root.
  Refinement problem{edges, used, std::vector<int>(num_nodes, -1)};
  for (int node = 0; node < num_nodes; ++node) {
    if (result.registered[node] && node != result.root) {
      problem.variable[node] = problem.num_variables++;
    }
  }
  problem.tolerance = RadiansFromDegrees(options.rotation_tolerance_deg);
  bool l1_converged = true, irls_converged = true;
  if (problem.num_variables > 0) {
    l1_converged = L1Steps(problem, options.l1_iterations, &result);
    irls_converged = IrlsSteps(problem, options.irls_iterations,
                               RadiansFromDegrees(options.robust_scale_deg), &result);
  }
  result.converged = options.irls_iterations > 0 ? irls_converged : l1_converged;

  // 4. The residuals at the solution.
  MeasureResiduals(edges, used, &result);
  return result;
}

}  // namespace raytime
