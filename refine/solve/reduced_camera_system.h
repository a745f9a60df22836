// The ray-time LM's reduced camera system (paper §3.4; PoseLib's accumulator): the damped normal
// equations of the poses after each one-dimensional ray time is eliminated in closed form, the
// Schur complement Ceres' SPARSE_SCHUR factorizes too. The linearization
// (ray_time_lm_linearization.h) writes each fixed chunk's share of it (fixed_chunks.h:
// bit-identical on any thread count); the system adds the shares in chunk order, solves for the
// cameras' step at a trust-region radius and recovers the ray times' step by back-substitution.
//
// Why its own storage, not a generic sparse matrix: the pattern is fixed for a solve (which images
// a ray time couples) and known before any value, so every residual's contribution goes to a block
// found once, and the pattern is analyzed once by the sparse Cholesky.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <memory>
#include <vector>

#include "refine/solve/ray_time_lm_solver.h"

namespace raytime {

// The hot loops (per residual) use plain arrays and scalar code: Eigen's fixed-size kernels are
// templates whose out-of-line copies the linker may take from any other object instantiating them,
// e.g. an unoptimized test in the sanitizer build, where they made the solver 25x slower.
using Block6 = std::array<double, 36>;  // 6x6, row-major
using Row6 = std::array<double, 6>;

// Ceres' bounds on the LM diagonal (ceres::Solver::Options min_lm_diagonal, max_lm_diagonal), so
// that the damping means what it means in ceres_gnc.h.
inline constexpr double kMinLmDiagonal = 1e-6;
inline constexpr double kMaxLmDiagonal = 1e32;

// The LM damping of a variable with undamped curvature `diagonal` (an entry of diag(JᵀJ)) at
// trust-region radius μ: D/μ, D the diagonal clamped to [kMinLmDiagonal, kMaxLmDiagonal].
inline double LmDamping(double diagonal, double radius) {
  return std::min(std::max(diagonal, kMinLmDiagonal), kMaxLmDiagonal) / radius;
}

// The problem's fixed structure, as the reduction sees it: the images that are variables, each ray
// time's residual range, the camera pairs that couple (directly or through a ray time) and the
// chunks of the parallel linearization. The pose uncertainty (refine/checks/pose_uncertainty.h)
// reduces the same problem over the same structure.
class ReducedCameraPattern {
 public:
  // Throws std::invalid_argument when a ray time's residuals start from different observations
  // (RayTimeLmProblem's contract).
  explicit ReducedCameraPattern(const RayTimeLmProblem& problem);

  int num_variables() const { return num_variables_; }
  int num_ray_times() const { return static_cast<int>(residual_begin_.size()) - 1; }
  int num_blocks() const { return num_variables_ + static_cast<int>(neighbours_.size()); }
  // The variable of an image (its 6 columns at 6·variable), -1 for a held image.
  int variable(int image) const { return variable_[image]; }
  const std::vector<int>& variables() const { return variable_; }
  int residual_begin(int ray_time) const { return residual_begin_[ray_time]; }
  int residual_end(int ray_time) const { return residual_begin_[ray_time + 1]; }
  // The ray times of a fixed chunk (fixed_chunks.h), of about equal residual counts.
  int chunk_begin(int chunk) const { return chunk_begin_[chunk]; }
  int chunk_end(int chunk) const { return chunk_begin_[chunk + 1]; }

  // The variable images a ray time's residuals reach, ascending, from position
  // group_offset(ray_time) of all groups' entries (num_group_entries() in all).
  int group_offset(int ray_time) const { return group_begin_[ray_time]; }
  int num_group_entries() const { return static_cast<int>(group_cameras_.size()); }
  const int* group_begin(int ray_time) const {
    return group_cameras_.data() + group_begin_[ray_time];
  }
  const int* group_end(int ray_time) const {
    return group_cameras_.data() + group_begin_[ray_time + 1];
  }
  // The first of c's couplings with images after it (blocks num_variables + n for the n from
  // here on, ascending in the other image): a walk along it finds the blocks of a group's pairs.
  int first_neighbour(int c) const { return neighbour_begin_[c]; }
  int neighbour(int n) const { return neighbours_[n]; }
  int neighbour_end(int c) const { return neighbour_begin_[c + 1]; }

  // The block coupling residual k's source (rows when its variable is the lower) and target.
  int cross_block(int residual) const { return cross_block_[residual]; }

  // Block index of the coupling of variables c and d: c for c == d, else the pair's.
  int Block(int c, int d) const;

 private:
  void CheckRayTimesShareTheirSource(const RayTimeLmProblem& problem) const;
  void BuildGroups(const RayTimeLmProblem& problem);
  void BuildNeighbours();

  int num_variables_ = 0;
  std::vector<int> variable_;
  std::vector<int> residual_begin_;
  std::vector<int> group_begin_;
  std::vector<int> group_cameras_;
  std::vector<int> neighbour_begin_;
  std::vector<int> neighbours_;
  std::vector<int> chunk_begin_;
  std::vector<int> cross_block_;
};

// The cameras' and the ray times' step from the system, and the model's predicted cost decrease.
struct ReducedStep {
  Eigen::VectorXd cameras;  // 6 per variable camera: (φ, δO)
  std::vector<double> ray_times;
  double model_decrease = 0.0;
};

// The accumulator: per chunk a share of the system, their total, and per ray time what its
// back-substitution needs (its couplings with its group's cameras, its gradient and curvature).
class ReducedCameraSystem {
 public:
  explicit ReducedCameraSystem(const RayTimeLmProblem& problem);
  ~ReducedCameraSystem();

  const ReducedCameraPattern& pattern() const { return pattern_; }

  // One chunk's (or the total's) share of the linear system: the 6x6 blocks (diagonal blocks
  // first, lower triangle only, then the pairs c < d as rows c, columns d), the cameras' gradient
  // g, the elimination's share of the reduced right-hand side (which is -g + elimination), the
  // undamped diagonal of JᵀJ (for the LM damping) and the ray times' projected gradient max norm.
  struct Partial {
    std::vector<Block6> blocks;
    std::vector<Row6> gradient;
    std::vector<Row6> elimination;
    std::vector<Row6> diagonal;
    double gradient_max_norm = 0.0;
    void Reset(int num_blocks, int num_variables) {
      blocks.assign(num_blocks, Block6{});
      gradient.assign(num_variables, Row6{});
      elimination.assign(num_variables, Row6{});
      diagonal.assign(num_variables, Row6{});
      gradient_max_norm = 0.0;
    }
  };

  // What the linearization writes: a chunk's share, and per ray time its couplings H_ct (at its
  // group's entries), its gradient g_t and its undamped curvature h_tt.
  Partial& partial(int chunk) { return partials_[chunk]; }
  Row6* couplings(int ray_time) { return couplings_.data() + pattern_.group_offset(ray_time); }
  void SetRayTime(int ray_time, double gradient, double hessian) {
    ray_time_gradient_[ray_time] = gradient;
    ray_time_hessian_[ray_time] = hessian;
  }

  // The chunks' shares added in chunk order into the total, to which terms of the cameras alone
  // (the pose priors) are then added directly.
  void SumPartials();
  Partial& total() { return total_; }
  // The cameras' damping at radius μ (LmDamping of the total's diagonal), and the max norm of the
  // whole gradient (cameras, and ray times projected onto their bound).
  void Damp(double radius);
  double gradient_max_norm() const { return total_.gradient_max_norm; }

  // Solves the damped system (radius μ, as Damp and the linearization's elimination used) for
  // the cameras, back-substitutes the ray times and predicts the decrease; false when the system
  // could not be factorized.
  bool Solve(double radius, int num_threads, ReducedStep* step);

 private:
  double BackSubstitute(double radius, int num_threads, const Eigen::VectorXd& camera_step,
                        std::vector<double>* ray_time_step) const;

  ReducedCameraPattern pattern_;
  std::vector<Partial> partials_;
  Partial total_;
  std::vector<Row6> damping_;
  std::vector<Row6> couplings_;
  std::vector<double> ray_time_gradient_;
  std::vector<double> ray_time_hessian_;
  struct Factorization;
  std::unique_ptr<Factorization> factorization_;
};

}  // namespace raytime
