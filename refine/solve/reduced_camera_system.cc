#include "refine/solve/reduced_camera_system.h"

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>
#include <cmath>
#include <stdexcept>
#include <string>

#include "refine/solve/fixed_chunks.h"

namespace raytime {
namespace {

// The lower triangle of the damped reduced camera matrix as a scalar sparse matrix: which (row,
// column) each block fills.
void AssembleLower(const ReducedCameraPattern& pattern, const ReducedCameraSystem::Partial& total,
                   const std::vector<Row6>& damping, Eigen::SparseMatrix<double>* matrix) {
  const int num_variables = pattern.num_variables();
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(21 * num_variables + 36 * (pattern.num_blocks() - num_variables));
  for (int c = 0; c < num_variables; ++c) {
    for (int j = 0; j < 6; ++j) {
      for (int i = j; i < 6; ++i) {
        const double value = total.blocks[c][6 * i + j] + (i == j ? damping[c][i] : 0.0);
        triplets.emplace_back(6 * c + i, 6 * c + j, value);
      }
    }
    for (int n = pattern.first_neighbour(c); n < pattern.neighbour_end(c); ++n) {
      const int d = pattern.neighbour(n);
      const Block6& block = total.blocks[num_variables + n];
      for (int j = 0; j < 6; ++j) {
        for (int i = 0; i < 6; ++i) triplets.emplace_back(6 * d + i, 6 * c + j, block[6 * j + i]);
      }
    }
  }
  matrix->resize(6 * num_variables, 6 * num_variables);
  matrix->setFromTriplets(triplets.begin(), triplets.end());
}

}  // namespace

ReducedCameraPattern::ReducedCameraPattern(const RayTimeLmProblem& problem) {
  const int num_images = static_cast<int>(problem.world_from_cam.size());
  variable_.assign(num_images, -1);
  for (int i = 0; i < num_images; ++i) {
    if (!problem.held[i]) variable_[i] = num_variables_++;
  }
  const int num_ray_times = static_cast<int>(problem.ray_times.size());
  residual_begin_.assign(num_ray_times + 1, 0);
  for (const RayTimeLmResidual& r : problem.residuals) ++residual_begin_[r.ray_time + 1];
  for (int t = 0; t < num_ray_times; ++t) residual_begin_[t + 1] += residual_begin_[t];
  CheckRayTimesShareTheirSource(problem);
  BuildGroups(problem);
  BuildNeighbours();

  // Each residual's coupling block between its two images (-1: one is held, or both are the
  // same image), found once here rather than searched for in every linearization.
  cross_block_.assign(problem.residuals.size(), -1);
  for (size_t k = 0; k < problem.residuals.size(); ++k) {
    const int c = variable_[problem.residuals[k].source_image];
    const int d = variable_[problem.residuals[k].target_image];
    if (c >= 0 && d >= 0 && c != d) cross_block_[k] = Block(c, d);
  }
  chunk_begin_ = FixedChunkBounds(residual_begin_);
}

// A ray time lives on one observation: its residuals start from that observation's image and ray
// (the structured linearization sums their source terms before applying the lever).
void ReducedCameraPattern::CheckRayTimesShareTheirSource(const RayTimeLmProblem& problem) const {
  for (int t = 0; t < num_ray_times(); ++t) {
    if (residual_begin_[t] == residual_begin_[t + 1]) continue;
    const RayTimeLmResidual& first = problem.residuals[residual_begin_[t]];
    for (int k = residual_begin_[t] + 1; k < residual_begin_[t + 1]; ++k) {
      if (problem.residuals[k].source_image != first.source_image ||
          problem.residuals[k].source_ray != first.source_ray) {
        throw std::invalid_argument("ray time " + std::to_string(t) +
                                    ": its residuals start from different observations");
      }
    }
  }
}

// Each ray time's variable images, ascending: the images its elimination couples.
void ReducedCameraPattern::BuildGroups(const RayTimeLmProblem& problem) {
  group_begin_.assign(num_ray_times() + 1, 0);
  for (int t = 0; t < num_ray_times(); ++t) {
    const size_t begin = group_cameras_.size();
    for (int k = residual_begin_[t]; k < residual_begin_[t + 1]; ++k) {
      for (const int image :
           {problem.residuals[k].source_image, problem.residuals[k].target_image}) {
        const int c = variable_[image];
        if (c >= 0 && std::find(group_cameras_.begin() + begin, group_cameras_.end(), c) ==
                          group_cameras_.end()) {
          group_cameras_.push_back(c);
        }
      }
    }
    std::sort(group_cameras_.begin() + begin, group_cameras_.end());
    group_begin_[t + 1] = static_cast<int>(group_cameras_.size());
  }
}

// Coupled pairs (c < d): every two images of one group. Collected per image from the groups that
// hold it, deduplicated by a stamp per image: a list of every group's pairs holds Σ k(k-1)/2
// entries, which long tracks make huge (a 500-frame corridor walked four times, tracks of ~59
// frames: 850M pairs, 6.8 GB and a minute of sorting; docs/scaling.md).
void ReducedCameraPattern::BuildNeighbours() {
  std::vector<int> image_group_begin(num_variables_ + 1, 0);
  for (const int c : group_cameras_) ++image_group_begin[c + 1];
  for (int c = 0; c < num_variables_; ++c) image_group_begin[c + 1] += image_group_begin[c];
  std::vector<int> image_groups(group_cameras_.size());
  std::vector<int> next(image_group_begin.begin(), image_group_begin.end() - 1);
  for (int t = 0; t < num_ray_times(); ++t) {
    for (int g = group_begin_[t]; g < group_begin_[t + 1]; ++g) {
      image_groups[next[group_cameras_[g]]++] = t;
    }
  }
  std::vector<int> stamp(num_variables_, -1);
  neighbour_begin_.assign(num_variables_ + 1, 0);
  for (int c = 0; c < num_variables_; ++c) {
    const size_t row = neighbours_.size();
    for (int n = image_group_begin[c]; n < image_group_begin[c + 1]; ++n) {
      const int t = image_groups[n];
      for (int g = group_begin_[t]; g < group_begin_[t + 1]; ++g) {
        const int d = group_cameras_[g];
        if (d > c && stamp[d] != c) {
          stamp[d] = c;
          neighbours_.push_back(d);
        }
      }
    }
    std::sort(neighbours_.begin() + row, neighbours_.end());
    neighbour_begin_[c + 1] = static_cast<int>(neighbours_.size());
  }
  neighbours_.shrink_to_fit();
}

int ReducedCameraPattern::Block(int c, int d) const {
  if (c == d) return c;
  const int lo = std::min(c, d);
  const int hi = std::max(c, d);
  const auto first = neighbours_.begin() + neighbour_begin_[lo];
  const auto last = neighbours_.begin() + neighbour_begin_[lo + 1];
  return num_variables_ + static_cast<int>(std::lower_bound(first, last, hi) - neighbours_.begin());
}

// CHOLMOD's supernodal Cholesky (its own fill-reducing ordering, analyzed once per solve): the
// damped reduced system is positive definite. A sequence's system is banded and any sparse
// factorization is a few percent of an iteration; revisits (loop closures) fill the factor in,
// and there dense supernodes on BLAS took the linear solve from 6.9 to 2.2 s per iteration
// against Eigen's simplicial LDLᵀ (500 frames walked four times; docs/scaling.md).
struct ReducedCameraSystem::Factorization {
  Eigen::SparseMatrix<double> matrix;
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> llt;
  bool pattern_analyzed = false;
};

ReducedCameraSystem::ReducedCameraSystem(const RayTimeLmProblem& problem)
    : pattern_(problem),
      partials_(kNumFixedChunks),
      couplings_(pattern_.num_group_entries()),
      ray_time_gradient_(pattern_.num_ray_times()),
      ray_time_hessian_(pattern_.num_ray_times()),
      factorization_(std::make_unique<Factorization>()) {
  // A matrix that is not positive definite is an expected event (the step is rejected and the
  // damping raised), not a message for stdout, where the refine command writes its summary.
  factorization_->llt.cholmod().print = 0;
}

ReducedCameraSystem::~ReducedCameraSystem() = default;

void ReducedCameraSystem::SumPartials() {
  const int num_variables = pattern_.num_variables();
  total_.Reset(pattern_.num_blocks(), num_variables);
  for (const Partial& partial : partials_) {
    for (int b = 0; b < pattern_.num_blocks(); ++b) {
      for (int a = 0; a < 36; ++a) total_.blocks[b][a] += partial.blocks[b][a];
    }
    for (int c = 0; c < num_variables; ++c) {
      for (int a = 0; a < 6; ++a) {
        total_.gradient[c][a] += partial.gradient[c][a];
        total_.elimination[c][a] += partial.elimination[c][a];
        total_.diagonal[c][a] += partial.diagonal[c][a];
      }
    }
    total_.gradient_max_norm = std::max(total_.gradient_max_norm, partial.gradient_max_norm);
  }
}

void ReducedCameraSystem::Damp(double radius) {
  const int num_variables = pattern_.num_variables();
  damping_.resize(num_variables);
  for (int c = 0; c < num_variables; ++c) {
    for (int a = 0; a < 6; ++a) {
      damping_[c][a] = LmDamping(total_.diagonal[c][a], radius);
      total_.gradient_max_norm =
          std::max(total_.gradient_max_norm, std::abs(total_.gradient[c][a]));
    }
  }
}

bool ReducedCameraSystem::Solve(double radius, int num_threads, ReducedStep* step) {
  Factorization& f = *factorization_;
  AssembleLower(pattern_, total_, damping_, &f.matrix);
  if (!f.pattern_analyzed) {
    f.llt.analyzePattern(f.matrix);
    f.pattern_analyzed = true;
  }
  f.llt.factorize(f.matrix);
  step->model_decrease = 0.0;
  if (f.llt.info() != Eigen::Success) return false;
  Eigen::VectorXd rhs(6 * pattern_.num_variables());
  for (int c = 0; c < pattern_.num_variables(); ++c) {
    for (int a = 0; a < 6; ++a) rhs[6 * c + a] = total_.elimination[c][a] - total_.gradient[c][a];
  }
  step->cameras = f.llt.solve(rhs);
  step->model_decrease = BackSubstitute(radius, num_threads, step->cameras, &step->ray_times);
  return true;
}

// δt = (-g_t - H_tc δc) / h̃_t per ray time, and the model's decrease -(gᵀδ + ½ δᵀJᵀJδ). The step
// solves (JᵀJ + D)δ = -g, so δᵀJᵀJδ = -gᵀδ - δᵀDδ and the decrease is ½(δᵀDδ - gᵀδ): a sum of
// two non-negative terms, without re-linearizing a residual.
double ReducedCameraSystem::BackSubstitute(double radius, int num_threads,
                                           const Eigen::VectorXd& camera_step,
                                           std::vector<double>* ray_time_step) const {
  ray_time_step->resize(pattern_.num_ray_times());
  const double* steps = camera_step.data();
  std::vector<double> chunk_sums(kNumFixedChunks, 0.0);
  ForEachFixedChunk(num_threads, [&](int chunk) {
    double sum = 0.0;  // Σ (D_t δt² - g_t δt)
    for (int t = pattern_.chunk_begin(chunk); t < pattern_.chunk_end(chunk); ++t) {
      const int* group = pattern_.group_begin(t);
      const int group_size = static_cast<int>(pattern_.group_end(t) - group);
      const Row6* coupling = couplings_.data() + pattern_.group_offset(t);
      double rhs = -ray_time_gradient_[t];  // -g_t - H_tc δc
      for (int i = 0; i < group_size; ++i) {
        const double* step = steps + 6 * group[i];
        for (int a = 0; a < 6; ++a) rhs -= coupling[i][a] * step[a];
      }
      const double h_tt = ray_time_hessian_[t];
      const double damping = LmDamping(h_tt, radius);
      const double step = rhs / (h_tt + damping);
      (*ray_time_step)[t] = step;
      sum += damping * step * step - ray_time_gradient_[t] * step;
    }
    chunk_sums[chunk] = sum;
  });
  double sum = 0.0;
  for (const double s : chunk_sums) sum += s;
  for (int c = 0; c < pattern_.num_variables(); ++c) {
    for (int a = 0; a < 6; ++a) {
      const double step = steps[6 * c + a];
      sum += damping_[c][a] * step * step - total_.gradient[c][a] * step;
    }
  }
  return 0.5 * sum;
}

}  // namespace raytime
