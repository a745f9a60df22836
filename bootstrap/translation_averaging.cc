#include "bootstrap/translation_averaging.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "bootstrap/view_graph.h"
#include "core/geometry.h"
#include "core/statistics.h"

namespace raytime {
namespace {

// Weighted least-squares subproblem of one LUD round with the per-edge scales eliminated:
// min over gamma >= 1 of |D - gamma d|^2 is |P D|^2 + min(0, d.D - 1)^2 with P = I - d d^T and
// D = O_i - O_j. The sum over edges is convex and piecewise quadratic, so a semi-smooth Newton
// method with a backtracking line search solves it exactly in a few steps: once the set of edges
// held at gamma = 1 stops changing, the full Newton step lands on the minimum.
class LudSubproblem {
 public:
  LudSubproblem(const std::vector<RelativeDirection>& edges, const std::vector<int>& used,
                const std::vector<int>& variable, int num_variables)
      : edges_(edges), used_(used), variable_(variable), n_(num_variables) {}

  Eigen::Vector3d Position(const Eigen::VectorXd& x, int node) const {
    return variable_[node] < 0 ? Eigen::Vector3d::Zero()
                               : Eigen::Vector3d(x.segment<3>(3 * variable_[node]));
  }
  Eigen::Vector3d Delta(const Eigen::VectorXd& x, int k) const {
    const RelativeDirection& e = edges_[used_[k]];
    return Position(x, e.i) - Position(x, e.j);
  }
  // Squared distance of D to the ray {gamma d : gamma >= 1}.
  double EdgeCost(const Eigen::VectorXd& x, int k) const {
    const Eigen::Vector3d& d = edges_[used_[k]].direction;
    const Eigen::Vector3d delta = Delta(x, k);
    const double along = d.dot(delta);
    return (delta - along * d).squaredNorm() + (along < 1 ? (along - 1) * (along - 1) : 0.0);
  }
  double Cost(const Eigen::VectorXd& x, const std::vector<double>& w) const {
    double cost = 0.0;
    for (size_t k = 0; k < used_.size(); ++k) cost += w[k] * EdgeCost(x, static_cast<int>(k));
    return cost;
  }

  // Minimizes the weighted cost from x; returns the Newton iterations used.
  int Solve(const std::vector<double>& w, int max_iterations, Eigen::VectorXd* x) const {
    std::vector<bool> active = ActiveSet(*x);
    for (int it = 0; it < max_iterations; ++it) {
      Eigen::VectorXd gradient = Eigen::VectorXd::Zero(3 * n_);
      std::vector<Eigen::Triplet<double>> triplets;
      triplets.reserve(used_.size() * 36 + 3 * n_);
      double diagonal = 0.0;
      for (size_t k = 0; k < used_.size(); ++k) {
        const RelativeDirection& e = edges_[used_[k]];
        const Eigen::Vector3d& d = e.direction;
        const Eigen::Vector3d delta = Delta(*x, static_cast<int>(k));
        const double along = d.dot(delta);
        const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - d * d.transpose();
        Eigen::Vector3d g = projector * delta;
        Eigen::Matrix3d h = projector;
        if (active[k]) {
          g += (along - 1) * d;
          h = Eigen::Matrix3d::Identity();
        }
        g *= w[k];
        h *= w[k];
        diagonal += 2 * h.trace();
        const int vi = variable_[e.i], vj = variable_[e.j];
        if (vi >= 0) gradient.segment<3>(3 * vi) += g;
        if (vj >= 0) gradient.segment<3>(3 * vj) -= g;
        AddBlock(vi, vi, h, &triplets);
        AddBlock(vj, vj, h, &triplets);
        AddBlock(vi, vj, -h, &triplets);
        AddBlock(vj, vi, -h, &triplets);
      }
      // A vanishing Tikhonov term keeps the matrix definite while no edge is held at gamma = 1
      // (the overall scale is then unconstrained to second order).
      const double ridge = 1e-12 * std::max(1.0, diagonal / (3 * n_));
      for (int r = 0; r < 3 * n_; ++r) triplets.emplace_back(r, r, ridge);
      Eigen::SparseMatrix<double> hessian(3 * n_, 3 * n_);
      hessian.setFromTriplets(triplets.begin(), triplets.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(hessian);
      if (solver.info() != Eigen::Success) {
        throw std::runtime_error("translation averaging: normal matrix is not factorizable");
      }
      const Eigen::VectorXd step = solver.solve(-gradient);
      const double slope = gradient.dot(step);
      if (!(slope < 0)) return it;  // already at the minimum to machine precision
      const double cost = Cost(*x, w);
      double alpha = 1.0;
      Eigen::VectorXd trial = *x + step;
      while (Cost(trial, w) > cost + 1e-4 * alpha * slope && alpha > 1e-10) {
        alpha *= 0.5;
        trial = *x + alpha * step;
      }
      *x = trial;
      const std::vector<bool> next = ActiveSet(*x);
      if (alpha == 1.0 && next == active) return it + 1;
      active = next;
    }
    return max_iterations;
  }

 private:
  std::vector<bool> ActiveSet(const Eigen::VectorXd& x) const {
    std::vector<bool> active(used_.size());
    for (size_t k = 0; k < used_.size(); ++k) {
      active[k] = edges_[used_[k]].direction.dot(Delta(x, static_cast<int>(k))) < 1.0;
    }
    return active;
  }
  static void AddBlock(int row, int col, const Eigen::Matrix3d& block,
                       std::vector<Eigen::Triplet<double>>* triplets) {
    if (row < 0 || col < 0) return;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) triplets->emplace_back(3 * row + r, 3 * col + c, block(r, c));
    }
  }

  const std::vector<RelativeDirection>& edges_;
  const std::vector<int>& used_;
  const std::vector<int>& variable_;
  const int n_;
};

}  // namespace

TranslationAveragingResult AverageTranslations(int num_nodes,
                                               const std::vector<RelativeDirection>& edges,
                                               const TranslationAveragingOptions& options) {
  ValidateOptions(options, "translation averaging");
  if (num_nodes < 0) throw std::invalid_argument("AverageTranslations: negative node count");
  std::vector<std::pair<int, int>> pairs;
  for (const auto& e : edges) {
    if (e.i < 0 || e.j < 0 || e.i >= num_nodes || e.j >= num_nodes || e.i == e.j) {
      throw std::invalid_argument("AverageTranslations: bad edge (" + std::to_string(e.i) + ", " +
                                  std::to_string(e.j) + ") for " + std::to_string(num_nodes) +
                                  " nodes");
    }
    if (!e.direction.allFinite() || std::abs(e.direction.norm() - 1.0) > 1e-6) {
      throw std::invalid_argument("AverageTranslations: edge (" + std::to_string(e.i) + ", " +
                                  std::to_string(e.j) + ") direction is not a unit vector");
    }
    pairs.emplace_back(e.i, e.j);
  }
  TranslationAveragingResult result;
  result.centres.assign(num_nodes, Eigen::Vector3d::Zero());
  result.registered.assign(num_nodes, false);
  result.edge_residual_deg.assign(edges.size(), std::numeric_limits<double>::quiet_NaN());
  result.edge_scale.assign(edges.size(), std::numeric_limits<double>::quiet_NaN());
  if (num_nodes == 0 || edges.empty()) return result;

  const std::vector<int> labels = ConnectedComponents(num_nodes, pairs);
  std::vector<int> used;
  for (size_t k = 0; k < edges.size(); ++k) {
    if (labels[edges[k].i] == 0) used.push_back(static_cast<int>(k));
  }
  // Gauge: the first node of the component stays at the origin during the solve.
  std::vector<int> variable(num_nodes, -1);
  int num_variables = 0, root = -1;
  for (int node = 0; node < num_nodes; ++node) {
    if (labels[node] != 0) continue;
    result.registered[node] = true;
    if (root < 0) {
      root = node;
    } else {
      variable[node] = num_variables++;
    }
  }
  result.num_registered = num_variables + 1;
  result.num_edges_used = static_cast<int>(used.size());

  const LudSubproblem problem(edges, used, variable, num_variables);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(3 * num_variables);
  std::vector<double> weights(used.size(), 1.0);
  for (int round = 0; round < options.lud_iterations; ++round) {
    const Eigen::VectorXd previous = x;
    problem.Solve(weights, options.lud_newton_iterations, &x);
    ++result.iterations;
    for (size_t k = 0; k < used.size(); ++k) {
      weights[k] =
          1.0 / std::max(std::sqrt(problem.EdgeCost(x, static_cast<int>(k))), options.lud_delta);
    }
    if (round > 0 && (x - previous).lpNorm<Eigen::Infinity>() < options.lud_tolerance) {
      result.converged = true;
      break;
    }
  }

  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int node = 0; node < num_nodes; ++node) {
    if (result.registered[node]) centroid += problem.Position(x, node);
  }
  centroid /= result.num_registered;
  for (int node = 0; node < num_nodes; ++node) {
    if (result.registered[node]) result.centres[node] = problem.Position(x, node) - centroid;
  }
  std::vector<double> residuals;
  for (size_t k = 0; k < used.size(); ++k) {
    const RelativeDirection& e = edges[used[k]];
    const Eigen::Vector3d delta = problem.Delta(x, static_cast<int>(k));
    const double angle = std::atan2(e.direction.cross(delta).norm(), e.direction.dot(delta));
    result.edge_residual_deg[used[k]] = DegreesFromRadians(angle);
    result.edge_scale[used[k]] = std::max(1.0, e.direction.dot(delta));
    residuals.push_back(result.edge_residual_deg[used[k]]);
  }
  result.mean_residual_deg = FiniteMean(residuals);
  result.median_residual_deg = FiniteUpperMedian(residuals);
  return result;
}

}  // namespace raytime
