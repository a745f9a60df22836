#include "refine/solve/ray_time_lm_solver.h"

#include <spdlog/spdlog.h>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <Eigen/CholmodSupport>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/timing.h"
#include "refine/solve/fixed_chunks.h"
#include "refine/solve/ray_geometry.h"

#if defined(__x86_64__)
// glibc's vector atan for AVX2 (libmvec, since 2.35).
extern "C" __attribute__((target("avx2"))) __m256d _ZGVdN4v_atan(__m256d x);
#endif

namespace raytime {
namespace {

// The hot loops (per residual) use plain arrays and scalar code: Eigen's fixed-size kernels are
// templates whose out-of-line copies the linker may take from any other object instantiating them,
// e.g. an unoptimized test in the sanitizer build, where they made the solver 25x slower.
using Block6 = std::array<double, 36>;  // 6x6, row-major
using Row6 = std::array<double, 6>;

// Ceres' trust-region defaults (ceres::Solver::Options), so that an iteration limit or tolerance
// set for ceres_gnc.h means the same here.
constexpr double kInitialRadius = 1e4;
constexpr double kMaxRadius = 1e16;
constexpr double kMinRadius = 1e-32;
constexpr double kMinLmDiagonal = 1e-6;
constexpr double kMaxLmDiagonal = 1e32;
constexpr double kMinRelativeDecrease = 1e-3;
constexpr double kGradientTolerance = 1e-10;
// Step doubling (SolveStage) after an accepted step whose actual decrease beat the model's by this
// factor: 1 is a model that is exact along the step, 2 a cost that is linear along it.
constexpr double kStepDoublingMinRelativeDecrease = 1.5;
constexpr double kParameterTolerance = 1e-8;
// The linearization, the cost and the back-substitution run over fixed chunks of ray times
// (fixed_chunks.h), each linearization chunk into its own copy of the reduced system.

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

double Clamp(double value) { return std::min(std::max(value, kMinLmDiagonal), kMaxLmDiagonal); }

// block += s·a·bᵀ, 6x6 row-major.
inline void AddScaledOuter(double* __restrict block, const double* __restrict a,
                           const double* __restrict b, double s) {
  for (int i = 0; i < 6; ++i) {
    const double ai = s * a[i];
    for (int j = 0; j < 6; ++j) block[6 * i + j] += ai * b[j];
  }
}

// The lower triangle (j <= i) of block += s·a·aᵀ: a camera's diagonal block is symmetric and
// only its lower triangle is assembled, so the upper one is never accumulated.
inline void AddScaledLowerOuter(double* __restrict block, const double* __restrict a, double s) {
  for (int i = 0; i < 6; ++i) {
    const double ai = s * a[i];
    for (int j = 0; j <= i; ++j) block[6 * i + j] += ai * a[j];
  }
}

// The pose prior of one image (refine/solve/pose_prior_cost.h) in the local parameters (φ, δO):
// r = (sR·Log(R_priorᵀ R), sp·(O - O_prior)) with Jacobian blocks A = sR·Jr⁻¹(θ)·Rᵀ for φ and
// sp·I for δO (R ← Exp(φ)·R gives Log(R_priorᵀ Exp(φ) R) ≈ θ + Jr⁻¹(θ)·Rᵀφ).
struct PriorLinearization {
  Eigen::Vector3d rotation_residual;
  Eigen::Vector3d centre_residual;
  Eigen::Matrix3d rotation_jacobian;
  double centre_scale = 0.0;
};

PriorLinearization LinearizePrior(const Rigid3& pose, const Rigid3& prior, double rotation_scale,
                                  double centre_scale) {
  PriorLinearization out;
  const Eigen::AngleAxisd log(prior.rotation.conjugate() * pose.rotation);
  const Eigen::Vector3d theta = log.angle() * log.axis();
  const double angle = log.angle();
  // Jr⁻¹(θ) = I + ½[θ]× + c·[θ]×², c = (1 - (θ/2)·cot(θ/2)) / θ² (1/12 at 0).
  const double c =
      angle < 1e-4 ? 1.0 / 12.0 : (1.0 - 0.5 * angle / std::tan(0.5 * angle)) / (angle * angle);
  const Eigen::Matrix3d skew = Skew(theta);
  const Eigen::Matrix3d jr_inv = Eigen::Matrix3d::Identity() + 0.5 * skew + c * skew * skew;
  out.rotation_residual = rotation_scale * theta;
  out.rotation_jacobian = rotation_scale * jr_inv * pose.rotation.toRotationMatrix().transpose();
  out.centre_residual = centre_scale * (pose.translation - prior.translation);
  out.centre_scale = centre_scale;
  return out;
}

// Every image's prior term at `world_from_cam`, with the weights of `problem` (λp/N, λR/N).
std::vector<PriorLinearization> LinearizePriors(const RayTimeLmProblem& problem,
                                                const std::vector<Rigid3>& world_from_cam) {
  const double rotation_scale = std::sqrt(2.0 * problem.orientation_weight);
  const double centre_scale = std::sqrt(2.0 * problem.position_weight);
  std::vector<PriorLinearization> priors;
  priors.reserve(world_from_cam.size());
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    priors.push_back(LinearizePrior(world_from_cam[i], problem.prior_world_from_cam[i],
                                    rotation_scale, centre_scale));
  }
  return priors;
}

// The reduced camera system's storage and the problem's fixed structure: the images that are
// variables, each ray time's residual range, the camera pairs that couple (directly or through a
// ray time) and the chunks of the parallel linearization.
class ReducedCameraSystem {
 public:
  explicit ReducedCameraSystem(const RayTimeLmProblem& problem) {
    const int num_images = static_cast<int>(problem.world_from_cam.size());
    variable_.assign(num_images, -1);
    for (int i = 0; i < num_images; ++i) {
      if (!problem.held[i]) variable_[i] = num_variables_++;
    }
    const int num_ray_times = static_cast<int>(problem.ray_times.size());
    residual_begin_.assign(num_ray_times + 1, 0);
    for (const RayTimeLmResidual& r : problem.residuals) ++residual_begin_[r.ray_time + 1];
    for (int t = 0; t < num_ray_times; ++t) residual_begin_[t + 1] += residual_begin_[t];

    // A ray time lives on one observation: its residuals start from that observation's image and
    // ray (the structured linearization sums their source terms before applying the lever).
    for (int t = 0; t < num_ray_times; ++t) {
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

    // Each ray time's variable images, ascending: the images its elimination couples.
    group_begin_.assign(num_ray_times + 1, 0);
    for (int t = 0; t < num_ray_times; ++t) {
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

    // Coupled pairs (c < d): every two images of one group. Collected per image from the groups
    // that hold it, deduplicated by a stamp per image: a list of every group's pairs holds
    // Σ k(k-1)/2 entries, which long tracks make huge (a 500-frame corridor walked four times,
    // tracks of ~59 frames: 850M pairs, 6.8 GB and a minute of sorting; docs/scaling.md).
    std::vector<int> image_group_begin(num_variables_ + 1, 0);
    for (const int c : group_cameras_) ++image_group_begin[c + 1];
    for (int c = 0; c < num_variables_; ++c) image_group_begin[c + 1] += image_group_begin[c];
    std::vector<int> image_groups(group_cameras_.size());
    std::vector<int> next(image_group_begin.begin(), image_group_begin.end() - 1);
    for (int t = 0; t < num_ray_times; ++t) {
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

    // Each residual's coupling block between its two images (-1: one is held, or both are the
    // same image), found once here rather than searched for in every linearization.
    cross_block_.assign(problem.residuals.size(), -1);
    for (size_t k = 0; k < problem.residuals.size(); ++k) {
      const int c = variable_[problem.residuals[k].source_image];
      const int d = variable_[problem.residuals[k].target_image];
      if (c >= 0 && d >= 0 && c != d) cross_block_[k] = Block(c, d);
    }

    // Chunks of ray times of about equal residual counts.
    chunk_begin_ = FixedChunkBounds(residual_begin_);
    partials_.resize(kNumFixedChunks);
  }

  int num_variables() const { return num_variables_; }
  int num_blocks() const { return num_variables_ + static_cast<int>(neighbours_.size()); }
  int variable(int image) const { return variable_[image]; }
  const std::vector<int>& variables() const { return variable_; }
  int residual_begin(int ray_time) const { return residual_begin_[ray_time]; }
  int residual_end(int ray_time) const { return residual_begin_[ray_time + 1]; }
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

  // The block coupling residual k's source (rows when its variable is the lower) and target.
  int cross_block(int residual) const { return cross_block_[residual]; }

  // Block index of the coupling of variables c and d: c for c == d, else the pair's.
  int Block(int c, int d) const {
    if (c == d) return c;
    const int lo = std::min(c, d);
    const int hi = std::max(c, d);
    const auto first = neighbours_.begin() + neighbour_begin_[lo];
    const auto last = neighbours_.begin() + neighbour_begin_[lo + 1];
    return num_variables_ +
           static_cast<int>(std::lower_bound(first, last, hi) - neighbours_.begin());
  }

  // One chunk's (or the total's) share of the linear system: the 6x6 blocks (diagonal blocks
  // first, lower triangle only, then the pairs c < d as rows c, columns d), the cameras' gradient
  // g, the elimination's
  // share of the reduced right-hand side (which is -g + elimination), the undamped diagonal of JᵀJ
  // (for the LM damping) and the ray times' projected gradient max norm.
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

  std::vector<Partial>& partials() { return partials_; }

  // Lower-triangle pattern of the scalar matrix: which (row, column) each block fills.
  void Assemble(const Partial& total, const std::vector<Row6>& damping,
                Eigen::SparseMatrix<double>* matrix) const {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(21 * num_variables_ + 36 * neighbours_.size());
    for (int c = 0; c < num_variables_; ++c) {
      for (int j = 0; j < 6; ++j) {
        for (int i = j; i < 6; ++i) {
          const double value = total.blocks[c][6 * i + j] + (i == j ? damping[c][i] : 0.0);
          triplets.emplace_back(6 * c + i, 6 * c + j, value);
        }
      }
      for (int n = neighbour_begin_[c]; n < neighbour_begin_[c + 1]; ++n) {
        const int d = neighbours_[n];
        const Block6& block = total.blocks[num_variables_ + n];
        for (int j = 0; j < 6; ++j) {
          for (int i = 0; i < 6; ++i) triplets.emplace_back(6 * d + i, 6 * c + j, block[6 * j + i]);
        }
      }
    }
    matrix->resize(6 * num_variables_, 6 * num_variables_);
    matrix->setFromTriplets(triplets.begin(), triplets.end());
  }

 private:
  int num_variables_ = 0;
  std::vector<int> variable_;
  std::vector<int> residual_begin_;
  std::vector<int> group_begin_;
  std::vector<int> group_cameras_;
  std::vector<int> neighbour_begin_;
  std::vector<int> neighbours_;
  std::vector<int> chunk_begin_;
  std::vector<int> cross_block_;
  std::vector<Partial> partials_;
};

// The current point: poses (with their rotation matrices, row-major, and centres as plain arrays
// for the hot loops) and ray times.
struct State {
  std::vector<Rigid3> world_from_cam;
  std::vector<std::array<double, 9>> rotation;
  std::vector<std::array<double, 3>> centre;
  std::vector<double> ray_times;

  void UpdateRotations() {
    rotation.resize(world_from_cam.size());
    centre.resize(world_from_cam.size());
    for (size_t i = 0; i < world_from_cam.size(); ++i) {
      const Eigen::Matrix3d r = world_from_cam[i].rotation.toRotationMatrix();
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) rotation[i][3 * a + b] = r(a, b);
        centre[i][a] = world_from_cam[i].translation[a];
      }
    }
  }
};

// r = π_t(O_s + t·R_s·d) - û and, when `source` is not null, its Jacobians (2x6 row-major in
// (φ, δO) of each pose, 2x1 in the ray time); R row-major, K = fx, fy, cx, cy. X moves with the
// source pose as dX = δO - [t R_s d]× φ, and p = R_tᵀ(X - O_t) with the target pose as
// dp = R_tᵀ(-δO + [v]× φ) (R ← Exp(φ) R, so Rᵀ ← Rᵀ Exp(-φ)). The value and ∂r/∂X are
// refine/solve/ray_geometry.h's, which every variant of the residual shares.
void CrossProjectionKernel(const double* rs, const double* os, double t, const double* rt,
                           const double* ot, const double* k, const double* d, const double* u,
                           double* r, double* source, double* ray_time, double* target) {
  double dir[3], point[3], v[3], p[3];
  RayPoint(rs, os, t, d, dir, point);
  TargetResidual(rt, ot, k, point, u, v, p, r);
  if (source == nullptr) return;
  const TargetResidualDerivative derivative = DifferentiateTargetResidual(rt, k, p);
  const double off[3] = {t * dir[0], t * dir[1], t * dir[2]};
  for (int a = 0; a < 2; ++a) {
    const double* m = derivative.du_dX[a];  // du_a/dX = du_a/dp · R_tᵀ
    ray_time[a] = m[0] * dir[0] + m[1] * dir[1] + m[2] * dir[2];
    double* js = source + 6 * a;
    double* jt = target + 6 * a;
    js[0] = off[1] * m[2] - off[2] * m[1];  // off × m
    js[1] = off[2] * m[0] - off[0] * m[2];
    js[2] = off[0] * m[1] - off[1] * m[0];
    jt[0] = m[1] * v[2] - m[2] * v[1];  // m × v
    jt[1] = m[2] * v[0] - m[0] * v[2];
    jt[2] = m[0] * v[1] - m[1] * v[0];
    for (int c = 0; c < 3; ++c) {
      js[3 + c] = m[c];
      jt[3 + c] = -m[c];
    }
  }
}

double SquaredResidual(const RayTimeLmProblem& problem, const State& state,
                       const RayTimeLmResidual& r) {
  double e[2];
  CrossProjectionKernel(state.rotation[r.source_image].data(), state.centre[r.source_image].data(),
                        state.ray_times[r.ray_time], state.rotation[r.target_image].data(),
                        state.centre[r.target_image].data(), problem.pinhole[r.target_image].data(),
                        r.source_ray.data(), r.target_undistorted.data(), e, nullptr, nullptr,
                        nullptr);
  return e[0] * e[0] + e[1] * e[1];
}

double Cost(const RayTimeLmProblem& problem, const State& state, double scale_px2, int num_threads,
            const ReducedCameraSystem& system) {
  std::vector<double> chunk_sums(kNumFixedChunks, 0.0);
  ForEachFixedChunk(num_threads, [&](int chunk) {
    // The squared norms a block at a time, then their arctans together (SumOfArctans).
    constexpr int kBlock = 256;
    double squared_norms[kBlock];
    double sum = 0.0;
    const int begin = system.residual_begin(system.chunk_begin(chunk));
    const int end = system.residual_begin(system.chunk_end(chunk));
    for (int block = begin; block < end; block += kBlock) {
      const int size = std::min(kBlock, end - block);
      for (int k = 0; k < size; ++k) {
        squared_norms[k] = SquaredResidual(problem, state, problem.residuals[block + k]);
      }
      sum += SumOfArctans(squared_norms, size, scale_px2);
    }
    chunk_sums[chunk] = sum;
  });
  double cost = 0.0;
  for (const double sum : chunk_sums) cost += sum;
  // ρ(s) = w·a·atan(s/a) (ScaledArctanLoss), summed.
  cost *= problem.match_loss_weight * scale_px2;
  double prior = 0.0;
  for (const PriorLinearization& p : LinearizePriors(problem, state.world_from_cam)) {
    prior += p.rotation_residual.squaredNorm() + p.centre_residual.squaredNorm();
  }
  return 0.5 * (cost + prior);
}

// The structured linearization. A residual's Jacobians all factor through M = ∂r/∂X (2x3, the
// target projection's derivative at the ray point X): the source pose's rows are B_s·m_a with
// B_s = [[o]×; I] (o = t·R_s·d, the ray point's offset from the source centre), the target's
// -[[v]×; I]·m_a (v = X - O_t) and the ray time's dᵀ·m_a (d = R_s·d_cam), m_a the rows of M. So
// with Q = w·MᵀM (3x3) and q = w·Mᵀr every product the reduced system needs is B·Q·Bᵀ, B·q or
// B·Q·d, fewer operations than forming the 2x6 Jacobians and their products, and all of a ray
// time's residuals share its source lever B_s, so the source's terms are summed as Q and applied
// once per ray time (fountain-P11, 181k residuals: 28 -> 21 ms per linearization on one thread).

// p = [x]×·Q for a symmetric 3x3 Q (row-major).
inline void SkewTimes(const double* x, const double* q, double* p) {
  for (int j = 0; j < 3; ++j) {
    p[j] = x[1] * q[6 + j] - x[2] * q[3 + j];
    p[3 + j] = x[2] * q[j] - x[0] * q[6 + j];
    p[6 + j] = x[0] * q[3 + j] - x[1] * q[j];
  }
}

// out = x × y.
inline void Cross(const double* x, const double* y, double* out) {
  out[0] = x[1] * y[2] - x[2] * y[1];
  out[1] = x[2] * y[0] - x[0] * y[2];
  out[2] = x[0] * y[1] - x[1] * y[0];
}

// The lower triangle of block += B·Q·Bᵀ for B = [[x]×; I] (6x3), given p = [x]×·Q, and its
// diagonal into `diagonal`: [[x]×Q[x]×ᵀ, ·; Q[x]×ᵀ, Q], whose row i of [x]×Q[x]×ᵀ is x × p_i.
// Written out entry by entry: a temporary row array that the compiler then read back as packed
// pairs stalled on store forwarding (perf: the hottest instructions of the linearization).
inline void AddLeverGram(const double* x, const double* q, const double* p, double* block,
                         double* diagonal) {
  const double r00 = x[1] * p[2] - x[2] * p[1];
  const double r10 = x[1] * p[5] - x[2] * p[4];
  const double r11 = x[2] * p[3] - x[0] * p[5];
  const double r20 = x[1] * p[8] - x[2] * p[7];
  const double r21 = x[2] * p[6] - x[0] * p[8];
  const double r22 = x[0] * p[7] - x[1] * p[6];
  block[0] += r00;
  block[6] += r10;
  block[7] += r11;
  block[12] += r20;
  block[13] += r21;
  block[14] += r22;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) block[6 * (3 + i) + j] += p[3 * j + i];
  }
  block[21] += q[0];
  block[27] += q[3];
  block[28] += q[4];
  block[33] += q[6];
  block[34] += q[7];
  block[35] += q[8];
  diagonal[0] += r00;
  diagonal[1] += r11;
  diagonal[2] += r22;
  diagonal[3] += q[0];
  diagonal[4] += q[4];
  diagonal[5] += q[8];
}

// out = B·y for B = [[x]×; I] scaled by `sign`, added to the 6-vector out.
inline void AddLeverTimes(const double* x, const double* y, double sign, double* out) {
  double top[3];
  Cross(x, y, top);
  for (int a = 0; a < 3; ++a) {
    out[a] += sign * top[a];
    out[3 + a] += sign * y[a];
  }
}

// y = Q·x for a 3x3 row-major Q.
inline void Times3(const double* q, const double* x, double* y) {
  for (int a = 0; a < 3; ++a) y[a] = q[3 * a] * x[0] + q[3 * a + 1] * x[1] + q[3 * a + 2] * x[2];
}

// One residual's target terms within its ray time: the target camera (variable), the residual,
// v = X - O_t, Q = w·MᵀM, and Q·d.
struct TargetTerm {
  int camera = -1;
  int residual = -1;
  double v[3];
  double q[9];
  double qd[3];
};

// Adds the source-target block B_s·Z·B_tᵀ = -[[o]×·R, [o]×·Z; R, Z] (source rows i, target
// columns j) to block[i·row_stride + j·column_stride], with B_s = [[o]×; I], B_t = -[[v]×; I] and
// R = Z·[v]×ᵀ, whose row i is v × z_i: strides (6, 1) when the source is the block's row camera,
// (1, 6) when it is the column camera. Added in place: a 6x6 temporary added afterwards stalled on
// store forwarding.
inline void AddSourceTargetCoupling(const double* o, const double* v, const double* z,
                                    double* block, int row_stride, int column_stride) {
  double r[9];
  for (int i = 0; i < 3; ++i) {
    const double* zi = z + 3 * i;
    r[3 * i] = v[1] * zi[2] - v[2] * zi[1];
    r[3 * i + 1] = v[2] * zi[0] - v[0] * zi[2];
    r[3 * i + 2] = v[0] * zi[1] - v[1] * zi[0];
  }
  for (int j = 0; j < 3; ++j) {
    // Column j of [o]×·R and of [o]×·Z: o × (column j).
    const double r0 = r[j], r1 = r[3 + j], r2 = r[6 + j];
    const double z0 = z[j], z1 = z[3 + j], z2 = z[6 + j];
    double* left = block + j * column_stride;
    double* right = block + (3 + j) * column_stride;
    left[0] -= o[1] * r2 - o[2] * r1;
    left[row_stride] -= o[2] * r0 - o[0] * r2;
    left[2 * row_stride] -= o[0] * r1 - o[1] * r0;
    right[0] -= o[1] * z2 - o[2] * z1;
    right[row_stride] -= o[2] * z0 - o[0] * z2;
    right[2 * row_stride] -= o[0] * z1 - o[1] * z0;
    left[3 * row_stride] -= r0;
    left[4 * row_stride] -= r1;
    left[5 * row_stride] -= r2;
    right[3 * row_stride] -= z0;
    right[4 * row_stride] -= z1;
    right[5 * row_stride] -= z2;
  }
}

class Solver {
 public:
  Solver(RayTimeLmProblem* problem, int num_threads)
      : problem_(*problem), system_(*problem), num_threads_(num_threads) {
    state_.world_from_cam = problem->world_from_cam;
    for (Rigid3& pose : state_.world_from_cam) pose.rotation.normalize();
    state_.ray_times = problem->ray_times;
    state_.UpdateRotations();
    // A matrix that is not positive definite is an expected event (the step is rejected and the
    // damping raised), not a message for stdout, where the refine command writes its summary.
    factorization_.cholmod().print = 0;
  }

  GncStageSummary SolveStage(double scale_px2, int max_iterations, double function_tolerance,
                             int max_step_doublings, GncProgress* progress);

  void Store(RayTimeLmProblem* problem) const {
    problem->world_from_cam = state_.world_from_cam;
    problem->ray_times = state_.ray_times;
  }

 private:
  // Builds the damped reduced camera system at the current point (radius μ: damping D/μ).
  void BuildReducedSystem(const ScaledArctanLoss& loss, double radius);
  // One chunk of ray times' share of it: their residuals linearized, reduced and summed into the
  // chunk's Partial, their couplings kept for the back-substitution.
  // Cloned for AVX2 (dispatched at load time): the compiler's own vectorization of the loops
  // runs 4 doubles wide there instead of 2. No FMA in the clone, so nothing is contracted and the
  // results are the default clone's to the bit. Fountain-P11 8°, 1 thread: linearization 1.22-1.25
  // -> 1.11-1.14 s, the same final costs (three runs each).
  __attribute__((target_clones("avx2", "default"))) void LinearizeChunk(
      const ScaledArctanLoss& loss, double radius, int chunk);
  // From the cameras' step, the ray times' step (back-substitution from the couplings
  // BuildReducedSystem kept) and the model's predicted cost decrease -(gᵀδ + ½ δᵀJᵀJδ). The step
  // solves (JᵀJ + D)δ = -g, so δᵀJᵀJδ = -gᵀδ - δᵀDδ and the decrease is ½(δᵀDδ - gᵀδ): a sum of
  // two non-negative terms, without re-linearizing a residual.
  double BackSubstitute(double radius, const Eigen::VectorXd& camera_step,
                        std::vector<double>* ray_time_step) const;
  // *out = base ⊕ α·δ: the cameras by RetractPoses (the step's similarity part `similarity`
  // applied as a similarity), the ray times retracted in inverse depth (RetractRayTime) by their
  // step less the similarity's scaling, then scaled with it.
  void StepFrom(const State& base, const Eigen::VectorXd& camera_step,
                const Eigen::Matrix<double, 7, 1>& similarity,
                const std::vector<double>& ray_time_step, double alpha, State* out) const;

  const RayTimeLmProblem& problem_;
  ReducedCameraSystem system_;
  int num_threads_;
  State state_;
  ReducedCameraSystem::Partial total_;
  std::vector<Row6> damping_;
  // Per ray time at the point of the reduced system: its couplings H_ct with its group's cameras
  // (at the group's entries), its gradient g_t and its undamped h_tt.
  std::vector<Row6> couplings_;
  std::vector<double> ray_time_gradient_;
  std::vector<double> ray_time_hessian_;
  Eigen::SparseMatrix<double> matrix_;
  // CHOLMOD's supernodal Cholesky (its own fill-reducing ordering, analyzed once per solve): the
  // damped reduced system is positive definite. A sequence's system is banded and any sparse
  // factorization is a few percent of an iteration; revisits (loop closures) fill the factor in,
  // and there dense supernodes on BLAS took the linear solve from 6.9 to 2.2 s per iteration
  // against Eigen's simplicial LDLᵀ (500 frames walked four times; docs/scaling.md).
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> factorization_;
  bool pattern_analyzed_ = false;
};

__attribute__((target_clones("avx2", "default"))) void Solver::LinearizeChunk(
    const ScaledArctanLoss& loss, double radius, int chunk) {
  const int num_variables = system_.num_variables();
  ReducedCameraSystem::Partial& partial = system_.partials()[chunk];
  partial.Reset(system_.num_blocks(), num_variables);
  std::vector<TargetTerm> terms;
  for (int t = system_.chunk_begin(chunk); t < system_.chunk_end(chunk); ++t) {
    const int* group = system_.group_begin(t);
    const int group_size = static_cast<int>(system_.group_end(t) - group);
    Row6* coupling = couplings_.data() + system_.group_offset(t);  // per camera of the group
    std::fill(coupling, coupling + group_size, Row6{});
    auto slot = [&](int camera) {
      return coupling[std::lower_bound(group, group + group_size, camera) - group].data();
    };
    if (system_.residual_begin(t) == system_.residual_end(t)) {  // no match left on it
      ray_time_gradient_[t] = 0.0;
      ray_time_hessian_[t] = 0.0;
      continue;
    }
    // The ray time's observation: its residuals share the source image and ray (the problem's
    // contract, checked when the system is built), hence the ray point and the source lever.
    const RayTimeLmResidual& first = problem_.residuals[system_.residual_begin(t)];
    const int source = first.source_image;
    const int cs = system_.variable(source);
    double dir[3], point[3], lever[3];
    RayPoint(state_.rotation[source].data(), state_.centre[source].data(), state_.ray_times[t],
             first.source_ray.data(), dir, point);
    for (int a = 0; a < 3; ++a) lever[a] = state_.ray_times[t] * dir[a];
    double source_q[9] = {};  // Σ w·MᵀM over the ray time's residuals
    double source_g[3] = {};  // Σ w·Mᵀr
    terms.clear();
    for (int k = system_.residual_begin(t); k < system_.residual_end(t); ++k) {
      const RayTimeLmResidual& r = problem_.residuals[k];
      const int target = r.target_image;
      TargetTerm term;
      double p_cam[3], e[2];
      TargetResidual(state_.rotation[target].data(), state_.centre[target].data(),
                     problem_.pinhole[target].data(), point, r.target_undistorted.data(), term.v,
                     p_cam, e);
      const TargetResidualDerivative derivative = DifferentiateTargetResidual(
          state_.rotation[target].data(), problem_.pinhole[target].data(), p_cam);
      const double* m0 = derivative.du_dX[0];
      const double* m1 = derivative.du_dX[1];
      const double w = loss.Derivative(e[0] * e[0] + e[1] * e[1]);
      double g[3];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j <= i; ++j) {
          term.q[3 * i + j] = term.q[3 * j + i] = w * (m0[i] * m0[j] + m1[i] * m1[j]);
        }
        g[i] = w * (m0[i] * e[0] + m1[i] * e[1]);
      }
      for (int a = 0; a < 9; ++a) source_q[a] += term.q[a];
      for (int a = 0; a < 3; ++a) source_g[a] += g[a];
      term.camera = system_.variable(target);
      if (term.camera < 0) continue;
      term.residual = k;
      Times3(term.q, dir, term.qd);
      AddLeverTimes(term.v, g, -1.0, partial.gradient[term.camera].data());
      AddLeverTimes(term.v, term.qd, -1.0, slot(term.camera));
      terms.push_back(term);
    }
    double source_qd[3];
    Times3(source_q, dir, source_qd);
    const double h_tt = dir[0] * source_qd[0] + dir[1] * source_qd[1] + dir[2] * source_qd[2];
    const double g_t = dir[0] * source_g[0] + dir[1] * source_g[1] + dir[2] * source_g[2];
    ray_time_gradient_[t] = g_t;
    ray_time_hessian_[t] = h_tt;
    const double t_value = state_.ray_times[t];
    const double projected = std::max(t_value - g_t, kRayTimeLowerBound);
    partial.gradient_max_norm = std::max(partial.gradient_max_norm, std::abs(t_value - projected));
    if (cs >= 0) {
      AddLeverTimes(lever, source_g, 1.0, partial.gradient[cs].data());
      AddLeverTimes(lever, source_qd, 1.0, slot(cs));
    }

    // Eliminate the ray time: S -= H_ct H_tc / h̃, rhs += H_ct g_t / h̃ (signs: rhs = -g), with
    // H_ct = B_c·Q·d. When every camera of the group is one residual's target or the source
    // (the layouts' matches: one per image pair), the elimination's share of a camera's own block
    // and of the source-target coupling folds into the 3x3 middle factor, B·(Q - Q·d·dᵀ·Q'/h̃)·Bᵀ,
    // which is added once instead of the product and the correction separately.
    const double inverse = 1.0 / (h_tt + Clamp(h_tt) / radius);
    const bool folded = group_size == static_cast<int>(terms.size()) + (cs >= 0 ? 1 : 0);
    double z[9], p[9];
    auto fold = [&](const double* q, const double* left, const double* right) {
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          z[3 * i + j] = q[3 * i + j] - (folded ? left[i] * right[j] * inverse : 0.0);
        }
      }
    };
    auto add_diagonal_of_elimination = [&](int camera, const double* coupling_row) {
      // The damping's diag(JᵀJ) is the block's before the elimination.
      if (!folded) return;
      for (int a = 0; a < 6; ++a) {
        partial.diagonal[camera][a] += coupling_row[a] * coupling_row[a] * inverse;
      }
    };
    if (cs >= 0) {
      fold(source_q, source_qd, source_qd);
      SkewTimes(lever, z, p);
      AddLeverGram(lever, z, p, partial.blocks[cs].data(), partial.diagonal[cs].data());
      add_diagonal_of_elimination(cs, slot(cs));
    }
    for (const TargetTerm& term : terms) {
      fold(term.q, term.qd, term.qd);
      SkewTimes(term.v, z, p);
      AddLeverGram(term.v, z, p, partial.blocks[term.camera].data(),
                   partial.diagonal[term.camera].data());
      add_diagonal_of_elimination(term.camera, slot(term.camera));
      if (cs < 0) continue;
      fold(term.q, source_qd, term.qd);
      if (cs < term.camera) {
        AddSourceTargetCoupling(lever, term.v, z,
                                partial.blocks[system_.cross_block(term.residual)].data(), 6, 1);
      } else if (cs > term.camera) {
        AddSourceTargetCoupling(lever, term.v, z,
                                partial.blocks[system_.cross_block(term.residual)].data(), 1, 6);
      } else {
        // One image on both sides (the layouts skip such matches) couples it to itself: both
        // orders into its diagonal block (of which only the lower triangle is read).
        double* block = partial.blocks[cs].data();
        AddSourceTargetCoupling(lever, term.v, z, block, 6, 1);
        AddSourceTargetCoupling(lever, term.v, z, block, 1, 6);
      }
    }
    // The rest of the elimination: the right-hand side, and the products the fold did not take
    // (all of them when it did not apply). The group is ascending, so the blocks of (group[i],
    // group[j > i]) come in one walk along group[i]'s couplings: k²/2 pairs per ray time are the
    // solve's bulk with long tracks, and a search per pair was a fifth of it.
    const double scale = -inverse;
    for (int i = 0; i < group_size; ++i) {
      const int ci = group[i];
      double* elimination = partial.elimination[ci].data();
      for (int a = 0; a < 6; ++a) elimination[a] += coupling[i][a] * (g_t * inverse);
      if (!folded) AddScaledLowerOuter(partial.blocks[ci].data(), coupling[i].data(), scale);
      if (folded && ci == cs) continue;
      int n = system_.first_neighbour(ci);
      for (int j = i + 1; j < group_size; ++j) {
        if (folded && group[j] == cs) continue;
        while (system_.neighbour(n) < group[j]) ++n;
        AddScaledOuter(partial.blocks[num_variables + n].data(), coupling[i].data(),
                       coupling[j].data(), scale);
      }
    }
  }
}

void Solver::BuildReducedSystem(const ScaledArctanLoss& loss, double radius) {
  const int num_variables = system_.num_variables();
  std::vector<ReducedCameraSystem::Partial>& partials = system_.partials();
  couplings_.resize(system_.num_group_entries());
  ray_time_gradient_.resize(state_.ray_times.size());
  ray_time_hessian_.resize(state_.ray_times.size());
  ForEachFixedChunk(num_threads_, [&](int chunk) { LinearizeChunk(loss, radius, chunk); });

  total_.Reset(system_.num_blocks(), num_variables);
  for (const ReducedCameraSystem::Partial& partial : partials) {
    for (int b = 0; b < system_.num_blocks(); ++b) {
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

  // Pose priors: direct terms of each camera's diagonal block.
  const std::vector<PriorLinearization> priors = LinearizePriors(problem_, state_.world_from_cam);
  for (size_t i = 0; i < priors.size(); ++i) {
    const int c = system_.variable(static_cast<int>(i));
    if (c < 0) continue;
    const PriorLinearization& p = priors[i];
    const double centre_scale = p.centre_scale;
    const Eigen::Matrix3d ata = p.rotation_jacobian.transpose() * p.rotation_jacobian;
    const Eigen::Vector3d gradient = p.rotation_jacobian.transpose() * p.rotation_residual;
    Block6& block = total_.blocks[c];
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) block[6 * a + b] += ata(a, b);
      block[6 * (3 + a) + 3 + a] += centre_scale * centre_scale;
      total_.diagonal[c][a] += ata(a, a);
      total_.diagonal[c][3 + a] += centre_scale * centre_scale;
      total_.gradient[c][a] += gradient[a];
      total_.gradient[c][3 + a] += centre_scale * p.centre_residual[a];
    }
  }
  damping_.resize(num_variables);
  for (int c = 0; c < num_variables; ++c) {
    for (int a = 0; a < 6; ++a) {
      damping_[c][a] = Clamp(total_.diagonal[c][a]) / radius;
      total_.gradient_max_norm =
          std::max(total_.gradient_max_norm, std::abs(total_.gradient[c][a]));
    }
  }
}

double Solver::BackSubstitute(double radius, const Eigen::VectorXd& camera_step,
                              std::vector<double>* ray_time_step) const {
  ray_time_step->resize(state_.ray_times.size());
  const double* steps = camera_step.data();
  std::vector<double> chunk_sums(kNumFixedChunks, 0.0);
  ForEachFixedChunk(num_threads_, [&](int chunk) {
    double sum = 0.0;  // Σ (D_t δt² - g_t δt)
    for (int t = system_.chunk_begin(chunk); t < system_.chunk_end(chunk); ++t) {
      const int* group = system_.group_begin(t);
      const int group_size = static_cast<int>(system_.group_end(t) - group);
      const Row6* coupling = couplings_.data() + system_.group_offset(t);
      double rhs = -ray_time_gradient_[t];  // -g_t - H_tc δc
      for (int i = 0; i < group_size; ++i) {
        const double* step = steps + 6 * group[i];
        for (int a = 0; a < 6; ++a) rhs -= coupling[i][a] * step[a];
      }
      const double h_tt = ray_time_hessian_[t];
      const double damping = Clamp(h_tt) / radius;
      const double step = rhs / (h_tt + damping);
      (*ray_time_step)[t] = step;
      sum += damping * step * step - ray_time_gradient_[t] * step;
    }
    chunk_sums[chunk] = sum;
  });
  double sum = 0.0;
  for (const double s : chunk_sums) sum += s;
  for (int c = 0; c < system_.num_variables(); ++c) {
    for (int a = 0; a < 6; ++a) {
      const double step = steps[6 * c + a];
      sum += damping_[c][a] * step * step - total_.gradient[c][a] * step;
    }
  }
  return 0.5 * sum;
}

void Solver::StepFrom(const State& base, const Eigen::VectorXd& camera_step,
                      const Eigen::Matrix<double, 7, 1>& similarity,
                      const std::vector<double>& ray_time_step, double alpha, State* out) const {
  out->world_from_cam = base.world_from_cam;
  const Eigen::Matrix<double, 7, 1> scaled_similarity = alpha * similarity;
  RetractPoses(system_.variables(), alpha * camera_step, scaled_similarity, &out->world_from_cam);
  // A similarity scales every point's ray time by e^λ (X = O + t·R·d ↦ sQX + T).
  const double log_scale = scaled_similarity[3];
  const double scale = std::exp(log_scale);
  out->ray_times.resize(base.ray_times.size());
  for (size_t t = 0; t < base.ray_times.size(); ++t) {
    const double rest = alpha * ray_time_step[t] - log_scale * base.ray_times[t];
    out->ray_times[t] =
        std::max(scale * RetractRayTime(base.ray_times[t], rest), kRayTimeLowerBound);
  }
  out->UpdateRotations();
}

GncStageSummary Solver::SolveStage(double scale_px2, int max_iterations, double function_tolerance,
                                   int max_step_doublings, GncProgress* progress) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  const ScaledArctanLoss loss{scale_px2, problem_.match_loss_weight};
  GncStageSummary summary;
  summary.loss_scale_px2 = scale_px2;
  auto timed_cost = [&](const State& state) {
    const auto t0 = Clock::now();
    const double cost = Cost(problem_, state, scale_px2, num_threads_, system_);
    summary.residual_seconds += SecondsSince(t0);
    return cost;
  };
  double cost = timed_cost(state_);
  summary.initial_cost = cost;
  summary.termination = GncTermination::kNoConvergence;
  summary.message = "Maximum number of iterations reached.";
  double radius = kInitialRadius;
  double decrease_factor = 2.0;
  std::vector<double> ray_time_step;
  State candidate;
  State trial;
  Eigen::Matrix<double, 7, 1> similarity;
  while (summary.iterations < max_iterations) {
    auto t0 = Clock::now();
    BuildReducedSystem(loss, radius);
    ++summary.jacobian_evaluations;
    summary.jacobian_seconds += SecondsSince(t0);
    // Ceres' gradient test: the max norm of the full gradient (cameras, and ray times projected
    // onto their bound) at or below kGradientTolerance is a stationary point.
    if (total_.gradient_max_norm <= kGradientTolerance) {
      summary.termination = GncTermination::kConvergence;
      summary.message = "Gradient tolerance reached.";
      break;
    }
    t0 = Clock::now();
    system_.Assemble(total_, damping_, &matrix_);
    if (!pattern_analyzed_) {
      factorization_.analyzePattern(matrix_);
      pattern_analyzed_ = true;
    }
    factorization_.factorize(matrix_);
    const bool solved = factorization_.info() == Eigen::Success;
    Eigen::VectorXd camera_step;
    double model_decrease = 0.0;
    if (solved) {
      Eigen::VectorXd rhs(6 * system_.num_variables());
      for (int c = 0; c < system_.num_variables(); ++c) {
        for (int a = 0; a < 6; ++a) {
          rhs[6 * c + a] = total_.elimination[c][a] - total_.gradient[c][a];
        }
      }
      camera_step = factorization_.solve(rhs);
      model_decrease = BackSubstitute(radius, camera_step, &ray_time_step);
    }
    summary.linear_solver_seconds += SecondsSince(t0);
    ++summary.iterations;

    bool accepted = false;
    if (solved && std::isfinite(model_decrease) && model_decrease > 0.0) {
      // Candidate point: x ⊕ δ (StepFrom).
      similarity = SimilarityPart(state_.world_from_cam, system_.variables(), camera_step);
      StepFrom(state_, camera_step, similarity, ray_time_step, 1.0, &candidate);
      double step_norm2 = 0.0;
      double x_norm2 = 0.0;
      for (size_t i = 0; i < state_.world_from_cam.size(); ++i) {
        const Rigid3& pose = state_.world_from_cam[i];
        x_norm2 += pose.rotation.coeffs().squaredNorm() + pose.translation.squaredNorm();
        const int c = system_.variable(static_cast<int>(i));
        if (c >= 0) step_norm2 += camera_step.segment<6>(6 * c).squaredNorm();
      }
      // The parameter tolerance looks at the poses only: the points of far matches run out along
      // their rays (ray times of 1e7 where the scene is 40 deep, on fountain-P11), and with them
      // in |x| the test stopped the anneal after 4 of its ~30 steps. A ray time's step follows
      // from the cameras' (it is eliminated exactly), so still cameras mean a still solution.
      if (std::sqrt(step_norm2) <=
          kParameterTolerance * (std::sqrt(x_norm2) + kParameterTolerance)) {
        summary.termination = GncTermination::kConvergence;
        summary.message = "Parameter tolerance reached.";
        break;
      }
      const double candidate_cost = timed_cost(candidate);
      const double cost_change = cost - candidate_cost;
      const double relative_decrease = cost_change / model_decrease;
      accepted = std::isfinite(candidate_cost) && relative_decrease > kMinRelativeDecrease;
      if (std::isfinite(candidate_cost) && std::abs(cost_change) <= function_tolerance * cost) {
        if (accepted) {
          std::swap(state_, candidate);
          cost = candidate_cost;
          ++summary.successful_steps;
        }
        summary.termination = GncTermination::kConvergence;
        summary.message = "Function tolerance reached.";
        break;
      }
      if (accepted) {
        std::swap(state_, candidate);
        cost = candidate_cost;
        ++summary.successful_steps;
        // The step fell by much more than the model said: the arctan's IRLS weights overstate
        // the curvature along it (matches in the loss's bend being let go, the anneal's slow
        // creep: castle-P19 8°, 20 steps in one direction with 2x the predicted decrease each).
        // Doubling it while the cost keeps falling goes that way in one iteration; each try costs
        // one cost evaluation, a quarter of an iteration.
        if (relative_decrease > kStepDoublingMinRelativeDecrease) {
          const State& step_start = candidate;  // swapped out above: the point the step left
          double alpha = 1.0;
          for (int d = 0; d < max_step_doublings; ++d) {
            alpha *= 2.0;
            StepFrom(step_start, camera_step, similarity, ray_time_step, alpha, &trial);
            const double trial_cost = timed_cost(trial);
            if (!(trial_cost < cost)) break;
            std::swap(state_, trial);
            cost = trial_cost;
            ++summary.step_doublings;
          }
        }
        const double q = 2.0 * relative_decrease - 1.0;
        radius = std::min(kMaxRadius, radius / std::max(1.0 / 3.0, 1.0 - q * q * q));
        decrease_factor = 2.0;
      }
    }
    if (!accepted) {
      radius /= decrease_factor;
      decrease_factor *= 2.0;
      if (radius < kMinRadius) {
        summary.termination = solved ? GncTermination::kConvergence : GncTermination::kFailure;
        summary.message = solved ? "Minimum trust region radius reached."
                                 : "The reduced camera system could not be factorized.";
        break;
      }
    }
    progress->Report(summary.iterations, cost);
  }
  summary.final_cost = cost;
  summary.seconds = SecondsSince(start);
  return summary;
}

// The ray-time LM as the GNC driver's back-end (gnc.h).
class RayTimeLmStageBackend : public GncBackend {
 public:
  RayTimeLmStageBackend(RayTimeLmProblem* problem, int num_threads)
      : problem_(problem), solver_(problem, num_threads) {}
  GncStageSummary SolveStage(double scale_px2, double function_tolerance,
                             const GncSettings& settings, GncProgress* progress) override {
    return solver_.SolveStage(scale_px2, settings.max_iterations, function_tolerance,
                              settings.max_step_doublings, progress);
  }
  const char* Name() const override { return "ray-time LM"; }
  // The solver reads only the problem's sizes after it starts: storing into it mid-schedule is
  // safe.
  void Publish() override { solver_.Store(problem_); }

 private:
  RayTimeLmProblem* problem_;
  Solver solver_;
};

}  // namespace

#if defined(__x86_64__)
namespace {

__attribute__((target("avx2"))) double SumOfArctansAvx2(const double* s, int n, double scale) {
  const __m256d a = _mm256_set1_pd(scale);
  __m256d sum = _mm256_setzero_pd();
  int k = 0;
  for (; k + 4 <= n; k += 4) {
    sum = _mm256_add_pd(sum, _ZGVdN4v_atan(_mm256_div_pd(_mm256_loadu_pd(s + k), a)));
  }
  if (k < n) {
    double rest[4] = {0.0, 0.0, 0.0, 0.0};  // atan(0) = 0
    for (int j = 0; k + j < n; ++j) rest[j] = s[k + j];
    sum = _mm256_add_pd(sum, _ZGVdN4v_atan(_mm256_div_pd(_mm256_loadu_pd(rest), a)));
  }
  double lanes[4];
  _mm256_storeu_pd(lanes, sum);
  return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
}

}  // namespace
#endif

double SumOfArctans(const double* s, int n, double scale) {
#if defined(__x86_64__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2) return SumOfArctansAvx2(s, n, scale);
#endif
  double sum = 0.0;
  for (int k = 0; k < n; ++k) sum += std::atan(s[k] / scale);
  return sum;
}

Eigen::Matrix<double, 6, 7> SimilarityTangent(const Eigen::Vector3d& centre) {
  Eigen::Matrix<double, 6, 7> tangent = Eigen::Matrix<double, 6, 7>::Zero();
  tangent.block<3, 3>(0, 0).setIdentity();
  tangent.block<3, 3>(3, 0) = -Skew(centre);  // ω × O = -[O]× ω
  tangent.block<3, 1>(3, 3) = centre;
  tangent.block<3, 3>(3, 4).setIdentity();
  return tangent;
}

Eigen::Vector3d SimilarityPivot(const std::vector<Rigid3>& poses,
                                const std::vector<int>& variable) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int count = 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] < 0) continue;
    sum += poses[i].translation;
    ++count;
  }
  return count > 0 ? Eigen::Vector3d(sum / count) : sum;
}

Eigen::Matrix<double, 7, 1> SimilarityPart(const std::vector<Rigid3>& poses,
                                           const std::vector<int>& variable,
                                           const Eigen::VectorXd& step) {
  const Eigen::Vector3d pivot = SimilarityPivot(poses, variable);
  Eigen::Matrix<double, 7, 7> normal = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> rhs = Eigen::Matrix<double, 7, 1>::Zero();
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] < 0) continue;
    const Eigen::Matrix<double, 6, 7> tangent = SimilarityTangent(poses[i].translation - pivot);
    normal.noalias() += tangent.transpose() * tangent;
    rhs.noalias() += tangent.transpose() * step.segment<6>(6 * variable[i]);
  }
  // Fewer than three cameras, or all on one line, leave some of the 7 undetermined: the
  // minimum-norm part is still an exact similarity of the step.
  return normal.completeOrthogonalDecomposition().solve(rhs);
}

void RetractPoses(const std::vector<int>& variable, const Eigen::VectorXd& step,
                  const Eigen::Matrix<double, 7, 1>& similarity, std::vector<Rigid3>* poses) {
  const Eigen::Vector3d omega = similarity.head<3>();
  const double angle = omega.norm();
  const Eigen::Quaterniond rotation =
      angle > 0.0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle))
                  : Eigen::Quaterniond::Identity();
  const double scale = std::exp(similarity[3]);
  const Eigen::Vector3d pivot = SimilarityPivot(*poses, variable);
  for (size_t i = 0; i < poses->size(); ++i) {
    if (variable[i] < 0) continue;
    Rigid3& pose = (*poses)[i];
    const Eigen::Matrix<double, 6, 1> rest =
        step.segment<6>(6 * variable[i]) - SimilarityTangent(pose.translation - pivot) * similarity;
    const Eigen::Vector3d phi = rest.head<3>();
    const double phi_angle = phi.norm();
    if (phi_angle > 0.0) {
      pose.rotation =
          Eigen::Quaterniond(Eigen::AngleAxisd(phi_angle, phi / phi_angle)) * pose.rotation;
    }
    pose.translation += rest.tail<3>();
    pose.rotation = (rotation * pose.rotation).normalized();
    pose.translation =
        pivot + scale * (rotation * (pose.translation - pivot)) + similarity.tail<3>();
  }
}

double RetractRayTime(double ray_time, double step) {
  const double ratio = step / ray_time;
  const double retracted = ratio < 1.0 - 1.0 / kMaxRayTimeGrowth ? ray_time / (1.0 - ratio)
                                                                 : kMaxRayTimeGrowth * ray_time;
  return std::max(retracted, kRayTimeLowerBound);
}

void CrossProjectionJacobian(const Eigen::Matrix3d& source_rotation,
                             const Eigen::Vector3d& source_centre, double ray_time,
                             const Eigen::Matrix3d& target_rotation,
                             const Eigen::Vector3d& target_centre, const Eigen::Vector4d& pinhole,
                             const Eigen::Vector3d& source_ray,
                             const Eigen::Vector2d& target_undistorted, Eigen::Vector2d* residual,
                             Eigen::Matrix<double, 2, 6>* source_jacobian,
                             Eigen::Vector2d* ray_time_jacobian,
                             Eigen::Matrix<double, 2, 6>* target_jacobian) {
  double rs[9], rt[9];
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      rs[3 * a + b] = source_rotation(a, b);
      rt[3 * a + b] = target_rotation(a, b);
    }
  }
  double r[2], source[12], ray[2], target[12];
  CrossProjectionKernel(rs, source_centre.data(), ray_time, rt, target_centre.data(),
                        pinhole.data(), source_ray.data(), target_undistorted.data(), r, source,
                        ray, target);
  *residual << r[0], r[1];
  *ray_time_jacobian << ray[0], ray[1];
  for (int a = 0; a < 2; ++a) {
    for (int c = 0; c < 6; ++c) {
      (*source_jacobian)(a, c) = source[6 * a + c];
      (*target_jacobian)(a, c) = target[6 * a + c];
    }
  }
}

void PosePriorJacobian(const Rigid3& world_from_cam, const Rigid3& prior_world_from_cam,
                       double rotation_scale, double centre_scale,
                       Eigen::Matrix<double, 6, 1>* residual,
                       Eigen::Matrix<double, 6, 6>* jacobian) {
  const PriorLinearization p =
      LinearizePrior(world_from_cam, prior_world_from_cam, rotation_scale, centre_scale);
  residual->head<3>() = p.centre_residual;
  residual->tail<3>() = p.rotation_residual;
  jacobian->setZero();
  jacobian->block<3, 3>(0, 3) = p.centre_scale * Eigen::Matrix3d::Identity();
  jacobian->block<3, 3>(3, 0) = p.rotation_jacobian;
}

std::vector<GncStageSummary> SolveGncRayTimeLm(RayTimeLmProblem* problem,
                                               const GncSettings& settings) {
  RayTimeLmStageBackend backend(problem, settings.num_threads);
  std::vector<GncStageSummary> stages = SolveGnc(&backend, settings);
  backend.Publish();
  return stages;
}

}  // namespace raytime
