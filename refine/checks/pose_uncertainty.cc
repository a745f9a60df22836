#include "refine/checks/pose_uncertainty.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>

#include "core/geometry.h"
#include "core/json_fields.h"
#include "core/statistics.h"
#include "core/timing.h"
#include "refine/solve/arctan_loss.h"
#include "refine/solve/fixed_chunks.h"
#include "refine/solve/ray_time_lm_kernel.h"
#include "refine/solve/ray_time_lm_solver.h"
#include "refine/solve/reduced_camera_system.h"
#include "refine/solve/similarity_retraction.h"
#include "refine/solve/track_adjustment.h"

namespace raytime {
namespace {

using Matrix62 = Eigen::Matrix<double, 6, 2>;
using Matrix26 = Eigen::Matrix<double, 2, 6>;
// Blocks of a 6n-row matrix per variable camera, sparse (the few cameras a ray time or an
// observation reaches): an observation's noise columns, a ray time's H_tc.
template <class Block>
using SparseCameraBlocks = std::vector<std::pair<int, Block>>;
using CameraBlocks62 = SparseCameraBlocks<Matrix62>;

// Adds `value` to `camera`'s block; a held camera (-1) has none.
template <class Block>
void AddTo(SparseCameraBlocks<Block>* blocks, int camera, const Block& value) {
  if (camera < 0) return;
  for (auto& [c, block] : *blocks) {
    if (c == camera) {
      block += value;
      return;
    }
  }
  blocks->emplace_back(camera, value);
}

// ∂d/∂u of the unit ray d = normalize((u − cx)/fx, (v − cy)/fy, 1) at d.
Eigen::Matrix<double, 3, 2> RayDerivative(const Eigen::Vector3d& d,
                                          const Eigen::Vector4d& pinhole) {
  const Eigen::Matrix3d dd_dm = (Eigen::Matrix3d::Identity() - d * d.transpose()) * d.z();
  Eigen::Matrix<double, 3, 2> dm_du = Eigen::Matrix<double, 3, 2>::Zero();
  dm_du(0, 0) = 1.0 / pinhole(0);
  dm_du(1, 1) = 1.0 / pinhole(1);
  return dd_dm * dm_du;
}

// The sums of the σ estimate.
struct SigmaSums {
  double weighted_squares = 0.0;   // Σ a |r|²
  double weighted_expected = 0.0;  // Σ a tr(I + D Dᵀ)
  int num_residuals = 0;
  int num_ray_times = 0;  // those eliminated (H_tt > 0)
};
// The reduced camera matrix S (prior curvature included), the reduced gradient's covariance per
// unit σ² M = Σ_o N_o N_oᵀ (N_o an observation's noise blocks), and the sums of the σ estimate.
struct ReducedNoiseSystem {
  Eigen::MatrixXd S;
  Eigen::MatrixXd M;
  SigmaSums sums;
};

// A residual at the solution: its Jacobians, IRLS weight a = ρ'(|r|²) and D = ∂r/∂u_s.
struct Linearized {
  double a = 0.0;
  double squared_norm = 0.0;
  Matrix26 source, target;
  Eigen::Vector2d ray_time;
  Eigen::Matrix2d source_noise;
  int source_camera = -1;
  int target_camera = -1;
};

Linearized Linearize(const RayTimeLmProblem& problem, const std::vector<Eigen::Matrix3d>& rotation,
                     const ReducedCameraPattern& pattern, const ScaledArctanLoss& loss,
                     const RayTimeLmResidual& res) {
  Linearized lin;
  Eigen::Vector2d residual;
  const double t = problem.ray_times[res.ray_time];
  CrossProjectionJacobian(
      rotation[res.source_image], problem.world_from_cam[res.source_image].translation, t,
      rotation[res.target_image], problem.world_from_cam[res.target_image].translation,
      problem.pinhole[res.target_image], res.source_ray, res.target_undistorted, &residual,
      &lin.source, &lin.ray_time, &lin.target);
  lin.squared_norm = residual.squaredNorm();
  lin.a = loss.Derivative(lin.squared_norm);
  // ∂r/∂X is the source centre's block; X moves with d by t·R_s.
  lin.source_noise = t * lin.source.rightCols<3>() * rotation[res.source_image] *
                     RayDerivative(res.source_ray, problem.pinhole[res.source_image]);
  lin.source_camera = pattern.variable(res.source_image);
  lin.target_camera = pattern.variable(res.target_image);
  return lin;
}

// Sums of 6x6 blocks of a 6n x 6n matrix, kept per block in the order first touched (a chunk's
// share of S or M); AddTo(dense) adds them in that order, so a sum over chunks in chunk order is
// the same whatever thread ran which chunk.
class BlockSums {
 public:
  explicit BlockSums(int num_variable)
      : num_variable_(num_variable), slot_(size_t(num_variable) * num_variable, -1) {}
  Eigen::Matrix<double, 6, 6>& operator()(int c1, int c2) {
    int& slot = slot_[size_t(c1) * num_variable_ + c2];
    if (slot < 0) {
      slot = static_cast<int>(blocks_.size());
      blocks_.push_back({c1, c2, Eigen::Matrix<double, 6, 6>::Zero()});
    }
    return blocks_[slot].value;
  }
  void AddTo(Eigen::MatrixXd* dense) const {
    for (const Block& b : blocks_) dense->block<6, 6>(6 * b.c1, 6 * b.c2) += b.value;
  }

 private:
  struct Block {
    int c1, c2;
    Eigen::Matrix<double, 6, 6> value;
  };
  int num_variable_;
  std::vector<int> slot_;
  std::vector<Block> blocks_;
};

// What the elimination of the ray times keeps for the noise pass: per ray time its couplings H_tc
// with its group's cameras (at the pattern's group entries) and its curvature H_tt.
struct RayTimeElimination {
  std::vector<Eigen::Matrix<double, 6, 1>> coupling;
  std::vector<double> h_tt;
};

// The solve's rotations as matrices, once.
std::vector<Eigen::Matrix3d> RotationMatrices(const RayTimeLmProblem& problem) {
  std::vector<Eigen::Matrix3d> rotation(problem.world_from_cam.size());
  for (size_t i = 0; i < rotation.size(); ++i) {
    rotation[i] = problem.world_from_cam[i].rotation.toRotationMatrix();
  }
  return rotation;
}

// One ray time's residuals into S (their camera blocks, then the elimination S -= H_ct H_tc / H_tt)
// and into the σ estimate's sums.
void ReduceRayTime(const RayTimeLmProblem& problem, const std::vector<Eigen::Matrix3d>& rotation,
                   const ReducedCameraPattern& pattern, const ScaledArctanLoss& loss, int t,
                   RayTimeElimination* elimination, BlockSums* S, SigmaSums* sum) {
  const int* group = pattern.group_begin(t);
  const int group_size = static_cast<int>(pattern.group_end(t) - group);
  Eigen::Matrix<double, 6, 1>* coupling = elimination->coupling.data() + pattern.group_offset(t);
  auto coupling_of = [&](int camera) -> Eigen::Matrix<double, 6, 1>& {
    return coupling[std::lower_bound(group, group + group_size, camera) - group];
  };
  double& h_tt = elimination->h_tt[t];
  for (int k = pattern.residual_begin(t); k < pattern.residual_end(t); ++k) {
    const Linearized lin = Linearize(problem, rotation, pattern, loss, problem.residuals[k]);
    sum->weighted_squares += lin.a * lin.squared_norm;
    sum->weighted_expected += lin.a * (2.0 + lin.source_noise.squaredNorm());
    ++sum->num_residuals;
    h_tt += lin.a * lin.ray_time.squaredNorm();
    if (lin.source_camera >= 0) {
      coupling_of(lin.source_camera) += lin.a * lin.source.transpose() * lin.ray_time;
    }
    if (lin.target_camera >= 0) {
      coupling_of(lin.target_camera) += lin.a * lin.target.transpose() * lin.ray_time;
    }
    // The residual's own camera blocks of S.
    const std::pair<int, const Matrix26*> blocks[2] = {{lin.source_camera, &lin.source},
                                                       {lin.target_camera, &lin.target}};
    for (const auto& [c1, j1] : blocks) {
      if (c1 < 0) continue;
      for (const auto& [c2, j2] : blocks) {
        if (c2 >= 0) (*S)(c1, c2) += lin.a * j1->transpose() * *j2;
      }
    }
  }
  if (!(h_tt > 0.0)) return;
  ++sum->num_ray_times;
  for (int i = 0; i < group_size; ++i) {
    for (int j = 0; j < group_size; ++j) {
      (*S)(group[i], group[j]) -= coupling[i] * coupling[j].transpose() / h_tt;
    }
  }
}

// The reduced camera matrix S (without the priors) over the reduced camera system's pattern and
// its fixed chunks (fixed_chunks.h: the same bits on any thread count), the σ estimate's sums,
// and what the noise pass needs of the elimination.
void ReduceCameraMatrix(const RayTimeLmProblem& problem,
                        const std::vector<Eigen::Matrix3d>& rotation,
                        const ReducedCameraPattern& pattern, const ScaledArctanLoss& loss,
                        int num_threads, RayTimeElimination* elimination, ReducedNoiseSystem* out) {
  elimination->coupling.assign(pattern.num_group_entries(), Eigen::Matrix<double, 6, 1>::Zero());
  elimination->h_tt.assign(pattern.num_ray_times(), 0.0);
  std::vector<SigmaSums> sums(kNumFixedChunks);
  std::vector<BlockSums> s_blocks(kNumFixedChunks, BlockSums(pattern.num_variables()));
  ForEachFixedChunk(num_threads, [&](int chunk) {
    for (int t = pattern.chunk_begin(chunk); t < pattern.chunk_end(chunk); ++t) {
      ReduceRayTime(problem, rotation, pattern, loss, t, elimination, &s_blocks[chunk],
                    &sums[chunk]);
    }
  });
  const int n = 6 * pattern.num_variables();
  out->S = Eigen::MatrixXd::Zero(n, n);
  for (int chunk = 0; chunk < kNumFixedChunks; ++chunk) {
    s_blocks[chunk].AddTo(&out->S);
    out->sums.weighted_squares += sums[chunk].weighted_squares;
    out->sums.weighted_expected += sums[chunk].weighted_expected;
    out->sums.num_residuals += sums[chunk].num_residuals;
    out->sums.num_ray_times += sums[chunk].num_ray_times;
  }
}

// Each observation's residuals, in residual order: the ray time's (it is their source) and those
// it is the target of; `begin` the observations' n + 1 bounds into `residual`.
struct ObservationResiduals {
  std::vector<int> begin;
  std::vector<int> residual;
};

ObservationResiduals ResidualsByObservation(const std::vector<RayTimeLmResidual>& residuals) {
  int num_observations = 0;
  for (const RayTimeLmResidual& r : residuals) {
    num_observations =
        std::max({num_observations, r.source_observation + 1, r.target_observation + 1});
  }
  ObservationResiduals out;
  out.begin.assign(num_observations + 1, 0);
  for (const RayTimeLmResidual& r : residuals) {
    ++out.begin[r.source_observation + 1];
    ++out.begin[r.target_observation + 1];
  }
  for (int o = 0; o < num_observations; ++o) out.begin[o + 1] += out.begin[o];
  out.residual.resize(out.begin.back());
  std::vector<int> next(out.begin.begin(), out.begin.end() - 1);
  for (int k = 0; k < static_cast<int>(residuals.size()); ++k) {
    out.residual[next[residuals[k].source_observation]++] = k;
    out.residual[next[residuals[k].target_observation]++] = k;
  }
  return out;
}

// One observation's noise blocks N_o: the reduced gradient's part of each residual it moves,
// B = a (J − j_t H_tc / H_tt)ᵀ, carried to its keypoint (through the ray as the source, −I as
// the target). Each residual is linearized again here rather than kept: 45 doubles a residual.
void ObservationNoise(const RayTimeLmProblem& problem, const std::vector<Eigen::Matrix3d>& rotation,
                      const ReducedCameraPattern& pattern, const ScaledArctanLoss& loss,
                      const RayTimeElimination& elimination, const ObservationResiduals& by, int o,
                      CameraBlocks62* b, CameraBlocks62* noise) {
  noise->clear();
  for (int n = by.begin[o]; n < by.begin[o + 1]; ++n) {
    const int k = by.residual[n];
    const int t = problem.residuals[k].ray_time;
    const double h_tt = elimination.h_tt[t];
    if (!(h_tt > 0.0)) continue;
    const Linearized lin = Linearize(problem, rotation, pattern, loss, problem.residuals[k]);
    b->clear();
    const int* group = pattern.group_begin(t);
    const Eigen::Matrix<double, 6, 1>* coupling =
        elimination.coupling.data() + pattern.group_offset(t);
    for (int i = 0; i < static_cast<int>(pattern.group_end(t) - group); ++i) {
      AddTo<Matrix62>(b, group[i], -lin.a * coupling[i] * lin.ray_time.transpose() / h_tt);
    }
    AddTo<Matrix62>(b, lin.source_camera, lin.a * lin.source.transpose());
    AddTo<Matrix62>(b, lin.target_camera, lin.a * lin.target.transpose());
    const bool source = problem.residuals[k].source_observation == o;
    for (const auto& [c, block] : *b) {
      AddTo<Matrix62>(noise, c, source ? Matrix62(block * lin.source_noise) : Matrix62(-block));
    }
  }
}

// M = Σ_o N_o N_oᵀ over the observations' fixed chunks.
Eigen::MatrixXd NoiseCovariance(const RayTimeLmProblem& problem,
                                const std::vector<Eigen::Matrix3d>& rotation,
                                const ReducedCameraPattern& pattern, const ScaledArctanLoss& loss,
                                const RayTimeElimination& elimination, int num_threads) {
  const ObservationResiduals by = ResidualsByObservation(problem.residuals);
  std::vector<BlockSums> m_blocks(kNumFixedChunks, BlockSums(pattern.num_variables()));
  const std::vector<int> observation_chunks = FixedChunkBounds(by.begin);
  ForEachFixedChunk(num_threads, [&](int chunk) {
    BlockSums& M = m_blocks[chunk];
    CameraBlocks62 b;
    CameraBlocks62 noise;
    for (int o = observation_chunks[chunk]; o < observation_chunks[chunk + 1]; ++o) {
      ObservationNoise(problem, rotation, pattern, loss, elimination, by, o, &b, &noise);
      for (const auto& [c1, b1] : noise) {
        for (const auto& [c2, b2] : noise) M(c1, c2) += b1 * b2.transpose();
      }
    }
  });
  const int n = 6 * pattern.num_variables();
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(n, n);
  for (int chunk = 0; chunk < kNumFixedChunks; ++chunk) m_blocks[chunk].AddTo(&out);
  return out;
}

// The pose priors' curvature (noise-free: they hold the gauge the solve holds), per image with
// weights λp/N and λR/N towards `anchor`, into the blocks of the images `variable` maps to one.
void AddPriorCurvature(const std::vector<Rigid3>& world_from_cam, const std::vector<Rigid3>& anchor,
                       const std::vector<int>& variable, double position_weight,
                       double orientation_weight, Eigen::MatrixXd* S) {
  const double rotation_scale = std::sqrt(2.0 * orientation_weight);
  const double centre_scale = std::sqrt(2.0 * position_weight);
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    const int c = variable[i];
    if (c < 0) continue;
    Eigen::Matrix<double, 6, 1> residual;
    Eigen::Matrix<double, 6, 6> jacobian;
    PosePriorJacobian(world_from_cam[i], anchor[i], rotation_scale, centre_scale, &residual,
                      &jacobian);
    S->block<6, 6>(6 * c, 6 * c) += jacobian.transpose() * jacobian;
  }
}

// Why the covariance is not computed for `num_variable` cameras, or an empty string.
std::string CameraCountRefusal(int num_variable, int max_cameras) {
  if (num_variable < 2) return "fewer than two cameras reached by residuals";
  if (num_variable > max_cameras) {
    return std::to_string(num_variable) + " cameras, above max_cameras " +
           std::to_string(max_cameras) + " (dense covariance)";
  }
  return "";
}

std::string NoRedundancy(int num_scalar, int num_parameters) {
  return "no redundancy: " + std::to_string(num_scalar) + " scalar residuals for " +
         std::to_string(num_parameters) + " parameters";
}

// The reduction of the ray-time LM (reduced_camera_system.h) at the solution, undamped, over its
// pattern: first over the ray times, S and each ray time's couplings H_tc and curvature H_tt;
// then over the observations, M. Residuals are sorted by ray time (BuildRayTimeLmProblem).
ReducedNoiseSystem BuildReducedNoiseSystem(const RayTimeLmProblem& problem,
                                           const ReducedCameraPattern& pattern, double scale_px2,
                                           int num_threads) {
  const ScaledArctanLoss loss{scale_px2, problem.match_loss_weight};
  const std::vector<Eigen::Matrix3d> rotation = RotationMatrices(problem);
  ReducedNoiseSystem out;
  RayTimeElimination elimination;
  ReduceCameraMatrix(problem, rotation, pattern, loss, num_threads, &elimination, &out);
  out.M = NoiseCovariance(problem, rotation, pattern, loss, elimination, num_threads);
  AddPriorCurvature(problem.world_from_cam, problem.prior_world_from_cam, pattern.variables(),
                    problem.position_weight, problem.orientation_weight, &out.S);
  return out;
}

// The gauge polish, linearized: P = I − G·F with G the 7 similarity generators of the variable
// cameras (SimilarityTangent about their centroid, SimilarityPivot) and F = (GᵀWG)⁺GᵀW the weighted
// fit of a similarity to a displacement, W the polish's weights per camera.
struct GaugeFit {
  Eigen::MatrixXd generators;  // G, 6n × 7
  Eigen::MatrixXd fit;         // F, 7 × 6n
};

GaugeFit LinearizedGaugePolish(const std::vector<Rigid3>& world_from_cam,
                               const std::vector<int>& variable, int num_variables,
                               const PoseUncertaintySettings& settings) {
  const int n = 6 * num_variables;
  const Eigen::Vector3d pivot = SimilarityPivot(world_from_cam, variable);
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, 7);
  Eigen::VectorXd w(n);
  for (size_t i = 0; i < variable.size(); ++i) {
    const int c = variable[i];
    if (c < 0) continue;
    G.middleRows<6>(6 * c) = SimilarityTangent(world_from_cam[i].translation - pivot);
    w.segment<3>(6 * c).setConstant(settings.gauge_orientation_weight);
    w.segment<3>(6 * c + 3).setConstant(settings.gauge_position_weight);
  }
  const Eigen::MatrixXd WG = w.asDiagonal() * G;
  GaugeFit out;
  out.fit = (G.transpose() * WG).completeOrthogonalDecomposition().solve(WG.transpose());
  out.generators = std::move(G);
  return out;
}

// Each variable camera's covariance σ² A M Aᵀ with A = P S⁻¹ (P the gauge polish's projection),
// into summary->cameras (per image; `variable` maps an image to its camera block or -1) and the
// medians. False, with summary->reason, when S is not positive definite.
bool CovarianceOnTheGauge(const Eigen::MatrixXd& S, const Eigen::MatrixXd& M,
                          const std::vector<Rigid3>& world_from_cam,
                          const std::vector<int>& variable, int num_variables,
                          const PoseUncertaintySettings& settings,
                          PoseUncertaintySummary* summary) {
  const int n = 6 * num_variables;
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() != Eigen::Success) {
    summary->reason = "the reduced camera matrix is not positive definite";
    return false;
  }
  // Cov = σ² A M Aᵀ with A = P S⁻¹ = S⁻¹ − G (F S⁻¹); only its diagonal blocks are needed.
  Eigen::MatrixXd A = llt.solve(Eigen::MatrixXd::Identity(n, n));
  const GaugeFit gauge = LinearizedGaugePolish(world_from_cam, variable, num_variables, settings);
  A -= gauge.generators * (gauge.fit * A);
  // M is block-sparse (cameras that share observations): A·M costs n·nnz(M), not n³ (the
  // 457-frame desk: most of the estimate's time when dense).
  const Eigen::SparseMatrix<double> sparse_M = M.sparseView();
  const Eigen::MatrixXd AM = A * sparse_M;
  const double variance = summary->sigma_px * summary->sigma_px;

  std::vector<double> rotations, centres;
  for (size_t i = 0; i < variable.size(); ++i) {
    const int c = variable[i];
    if (c < 0) continue;
    PoseUncertainty& u = summary->cameras[i];
    const Eigen::Matrix<double, 6, 6> covariance =
        variance * AM.middleRows<6>(6 * c) * A.middleRows<6>(6 * c).transpose();
    u.rotation_deg =
        DegreesFromRadians(std::sqrt(std::max(0.0, covariance.topLeftCorner<3, 3>().trace())));
    u.centre = std::sqrt(std::max(0.0, covariance.bottomRightCorner<3, 3>().trace()));
    rotations.push_back(u.rotation_deg);
    centres.push_back(u.centre);
  }
  summary->median_rotation_deg = Median(rotations, 0.0);
  summary->median_centre = Median(centres, 0.0);
  summary->computed = true;
  return true;
}

}  // namespace

PoseUncertaintySummary EstimatePoseUncertainty(const RayTimeLmProblem& problem,
                                               const PoseUncertaintySettings& settings) {
  const auto start = std::chrono::steady_clock::now();
  PoseUncertaintySummary summary;
  summary.cameras.resize(problem.world_from_cam.size());
  const int num_variable =
      static_cast<int>(std::count(problem.held.begin(), problem.held.end(), false));
  summary.reason = CameraCountRefusal(num_variable, settings.max_cameras);
  if (!summary.reason.empty()) return summary;
  for (const RayTimeLmResidual& r : problem.residuals) {
    if (r.source_observation < 0 || r.target_observation < 0) {
      summary.reason = "residuals without their observations";
      return summary;
    }
  }
  const ReducedCameraPattern pattern(problem);
  const ReducedNoiseSystem system =
      BuildReducedNoiseSystem(problem, pattern, settings.scale_px2, settings.num_threads);
  const SigmaSums& sums = system.sums;
  const int num_scalar = 2 * sums.num_residuals;
  const int num_parameters = 6 * num_variable + sums.num_ray_times;
  if (num_scalar <= num_parameters || !(sums.weighted_expected > 0.0)) {
    summary.reason = NoRedundancy(num_scalar, num_parameters);
    return summary;
  }
  summary.sigma_px_estimated =
      std::sqrt(sums.weighted_squares / (sums.weighted_expected *
                                         (1.0 - static_cast<double>(num_parameters) / num_scalar)));
  summary.sigma_px = settings.sigma_px > 0.0 ? settings.sigma_px : summary.sigma_px_estimated;

  CovarianceOnTheGauge(system.S, system.M, problem.world_from_cam, pattern.variables(),
                       num_variable, settings, &summary);
  summary.seconds = SecondsSince(start);
  return summary;
}

namespace {

// The bundle adjustment's reduction at its solution: per track, the point's curvature H_pp, the
// cameras' couplings K_j = H_cjp H_pp⁻¹, S −= K H_pc and the observations' noise blocks
// N_o = a (e_o J_coᵀ − K J_poᵀ) into M (a the match term's weight 1/K), and Σ |r|².
struct TrackSystem {
  Eigen::MatrixXd S, M;
  double squares = 0.0;  // Σ |r|²
};

constexpr double kRelativeCurvatureFloor = 1e-9;

void ReduceTrack(const TrackAdjustmentProblem& problem, const std::vector<int>& observations,
                 const std::vector<int>& variable, double weight, TrackSystem* system) {
  const size_t m = observations.size();
  std::vector<Eigen::Matrix<double, 2, 6>> Jc(m);
  std::vector<Eigen::Matrix<double, 2, 3>> Jp(m);
  std::vector<double> a(m);
  std::vector<int> camera(m);
  Eigen::Matrix3d Hpp = Eigen::Matrix3d::Zero();
  for (size_t j = 0; j < m; ++j) {
    const int o = observations[j];
    system->squares += TrackResidualJacobians(problem, o, &Jc[j], &Jp[j]).squaredNorm();
    a[j] = weight;
    camera[j] = variable[problem.observation_image[o]];
    Hpp += a[j] * Jp[j].transpose() * Jp[j];
  }
  // A distant point's depth is barely constrained: inverted as it is, the rounding of that
  // direction can break S's positive definiteness (it did on a phone capture's low-parallax
  // points). Its couplings along it are as small, so it is left out (the pseudo-inverse).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(Hpp);
  const Eigen::Vector3d& values = eigen.eigenvalues();
  Eigen::Vector3d inverse_values = Eigen::Vector3d::Zero();
  for (int d = 0; d < 3; ++d) {
    if (values(d) > kRelativeCurvatureFloor * values(2)) inverse_values(d) = 1.0 / values(d);
  }
  const Eigen::Matrix3d Hpp_inverse =
      eigen.eigenvectors() * inverse_values.asDiagonal() * eigen.eigenvectors().transpose();
  std::vector<Eigen::Matrix<double, 6, 3>> K(m);
  for (size_t j = 0; j < m; ++j) K[j] = a[j] * Jc[j].transpose() * Jp[j] * Hpp_inverse;
  for (size_t j = 0; j < m; ++j) {
    if (camera[j] < 0) continue;
    system->S.block<6, 6>(6 * camera[j], 6 * camera[j]) += a[j] * Jc[j].transpose() * Jc[j];
    for (size_t l = 0; l < m; ++l) {
      if (camera[l] < 0) continue;
      system->S.block<6, 6>(6 * camera[j], 6 * camera[l]) -=
          K[j] * (a[l] * Jp[l].transpose() * Jc[l]);
    }
  }
  for (size_t o = 0; o < m; ++o) {
    std::vector<Eigen::Matrix<double, 6, 2>> N(m);
    for (size_t j = 0; j < m; ++j) {
      N[j] = -K[j] * (a[o] * Jp[o].transpose());
      if (j == o) N[j] += a[o] * Jc[o].transpose();
    }
    for (size_t j = 0; j < m; ++j) {
      if (camera[j] < 0) continue;
      for (size_t l = 0; l < m; ++l) {
        if (camera[l] >= 0) {
          system->M.block<6, 6>(6 * camera[j], 6 * camera[l]) += N[j] * N[l].transpose();
        }
      }
    }
  }
}

}  // namespace

PoseUncertaintySummary EstimateTrackPoseUncertainty(const TrackAdjustmentProblem& problem,
                                                    const PoseUncertaintySettings& settings) {
  const auto start = std::chrono::steady_clock::now();
  PoseUncertaintySummary summary;
  summary.estimator = "track_adjustment";
  const int num_images = static_cast<int>(problem.world_from_cam.size());
  summary.cameras.resize(num_images);
  const int num_observations = static_cast<int>(problem.observation_track.size());
  std::vector<int> variable(num_images, -1);
  for (const int image : problem.observation_image) variable[image] = 0;
  int num_variable = 0;
  for (int& v : variable) v = v < 0 ? -1 : num_variable++;
  summary.reason = CameraCountRefusal(num_variable, settings.max_cameras);
  if (!summary.reason.empty()) return summary;
  const int num_scalar = 2 * num_observations;
  const int num_parameters = 6 * num_variable + 3 * static_cast<int>(problem.points.size());
  if (num_scalar <= num_parameters) {
    summary.reason = NoRedundancy(num_scalar, num_parameters);
    return summary;
  }
  std::vector<std::vector<int>> by_track(problem.points.size());
  for (int o = 0; o < num_observations; ++o) by_track[problem.observation_track[o]].push_back(o);
  TrackSystem system;
  system.S = Eigen::MatrixXd::Zero(6 * num_variable, 6 * num_variable);
  system.M = system.S;
  for (const std::vector<int>& track : by_track) {
    if (track.size() >= 2) ReduceTrack(problem, track, variable, 1.0 / num_observations, &system);
  }
  AddPriorCurvature(problem.world_from_cam, problem.anchor, variable,
                    problem.position_weight / num_images, problem.orientation_weight / num_images,
                    &system.S);
  summary.sigma_px_estimated =
      std::sqrt(system.squares / (num_scalar - static_cast<double>(num_parameters)));
  summary.sigma_px = settings.sigma_px > 0.0 ? settings.sigma_px : summary.sigma_px_estimated;
  CovarianceOnTheGauge(system.S, system.M, problem.world_from_cam, variable, num_variable, settings,
                       &summary);
  summary.seconds = SecondsSince(start);
  return summary;
}

void to_json(nlohmann::json& json, const PoseUncertainty& uncertainty) {
  json = FieldsToJson(uncertainty);
}

void from_json(const nlohmann::json& json, PoseUncertainty& uncertainty) {
  uncertainty = FieldsFromJson<PoseUncertainty>(json);
}

}  // namespace raytime
