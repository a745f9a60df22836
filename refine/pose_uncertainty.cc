#include "refine/pose_uncertainty.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
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
#include "refine/ray_time_lm_solver.h"

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

// The reduced camera matrix S (prior curvature included), the reduced gradient's noise blocks per
// observation, and the sums of the σ estimate.
struct ReducedNoiseSystem {
  Eigen::MatrixXd S;
  std::vector<CameraBlocks62> noise_of_observation;
  double weighted_squares = 0.0;   // Σ a |r|²
  double weighted_expected = 0.0;  // Σ a tr(I + D Dᵀ)
  int num_residuals = 0;
  int num_ray_times = 0;
};

ReducedNoiseSystem BuildReducedNoiseSystem(const RayTimeLmProblem& problem,
                                           const std::vector<int>& variable, int num_variable,
                                           double scale_px2) {
  ReducedNoiseSystem out;
  out.S = Eigen::MatrixXd::Zero(6 * num_variable, 6 * num_variable);
  int num_observations = 0;
  for (const RayTimeLmResidual& r : problem.residuals) {
    num_observations =
        std::max({num_observations, r.source_observation + 1, r.target_observation + 1});
  }
  out.noise_of_observation.resize(num_observations);
  std::vector<Eigen::Matrix3d> rotation(problem.world_from_cam.size());
  for (size_t i = 0; i < rotation.size(); ++i) {
    rotation[i] = problem.world_from_cam[i].rotation.toRotationMatrix();
  }
  struct Linearized {
    double a;
    Matrix26 source, target;
    Eigen::Vector2d ray_time;
    Eigen::Matrix2d source_noise;  // D = ∂r/∂u_s
    int source_camera, target_camera, source_observation, target_observation;
  };
  std::vector<Linearized> group;
  // Scratch reused across ray times and residuals: allocating these per ray time and per residual
  // was most of the estimate's time.
  SparseCameraBlocks<Eigen::Matrix<double, 6, 1>> h_tc;
  CameraBlocks62 b;
  size_t begin = 0;
  while (begin < problem.residuals.size()) {
    const int t = problem.residuals[begin].ray_time;
    size_t end = begin;
    while (end < problem.residuals.size() && problem.residuals[end].ray_time == t) ++end;
    group.clear();
    h_tc.clear();
    double h_tt = 0.0;
    for (size_t k = begin; k < end; ++k) {
      const RayTimeLmResidual& res = problem.residuals[k];
      Linearized lin;
      Eigen::Vector2d residual;
      CrossProjectionJacobian(
          rotation[res.source_image], problem.world_from_cam[res.source_image].translation,
          problem.ray_times[t], rotation[res.target_image],
          problem.world_from_cam[res.target_image].translation, problem.pinhole[res.target_image],
          res.source_ray, res.target_undistorted, &residual, &lin.source, &lin.ray_time,
          &lin.target);
      const double s = residual.squaredNorm();
      lin.a = ScaledArctanLoss{scale_px2, problem.match_loss_weight}.Derivative(s);
      // ∂r/∂X is the source centre's block; X moves with d by t·R_s.
      lin.source_noise = problem.ray_times[t] * lin.source.rightCols<3>() *
                         rotation[res.source_image] *
                         RayDerivative(res.source_ray, problem.pinhole[res.source_image]);
      lin.source_camera = variable[res.source_image];
      lin.target_camera = variable[res.target_image];
      lin.source_observation = res.source_observation;
      lin.target_observation = res.target_observation;
      out.weighted_squares += lin.a * s;
      out.weighted_expected += lin.a * (2.0 + lin.source_noise.squaredNorm());
      ++out.num_residuals;
      h_tt += lin.a * lin.ray_time.squaredNorm();
      AddTo<Eigen::Matrix<double, 6, 1>>(&h_tc, lin.source_camera,
                                         lin.a * lin.source.transpose() * lin.ray_time);
      AddTo<Eigen::Matrix<double, 6, 1>>(&h_tc, lin.target_camera,
                                         lin.a * lin.target.transpose() * lin.ray_time);
      // The residual's own camera blocks of S.
      const std::pair<int, const Matrix26*> blocks[2] = {{lin.source_camera, &lin.source},
                                                         {lin.target_camera, &lin.target}};
      for (const auto& [c1, j1] : blocks) {
        if (c1 < 0) continue;
        for (const auto& [c2, j2] : blocks) {
          if (c2 < 0) continue;
          out.S.block<6, 6>(6 * c1, 6 * c2) += lin.a * j1->transpose() * *j2;
        }
      }
      group.push_back(lin);
    }
    if (h_tt > 0.0) {
      ++out.num_ray_times;
      for (const auto& [c1, v1] : h_tc) {
        for (const auto& [c2, v2] : h_tc) {
          out.S.block<6, 6>(6 * c1, 6 * c2) -= v1 * v2.transpose() / h_tt;
        }
      }
      // The reduced gradient's part of each residual, B = a (J − j_t H_tc / H_tt)ᵀ, carried to the
      // keypoints that move the residual.
      for (const Linearized& lin : group) {
        b.clear();
        for (const auto& [c, v] : h_tc) {
          AddTo<Matrix62>(&b, c, -lin.a * v * lin.ray_time.transpose() / h_tt);
        }
        AddTo<Matrix62>(&b, lin.source_camera, lin.a * lin.source.transpose());
        AddTo<Matrix62>(&b, lin.target_camera, lin.a * lin.target.transpose());
        // Every residual has both observations (EstimatePoseUncertainty checks).
        for (const auto& [c, block] : b) {
          AddTo<Matrix62>(&out.noise_of_observation[lin.source_observation], c,
                          block * lin.source_noise);
          AddTo<Matrix62>(&out.noise_of_observation[lin.target_observation], c, -block);
        }
      }
    }
    begin = end;
  }
  // The pose priors' curvature (noise-free: they hold the gauge the solve holds).
  const double rotation_scale = std::sqrt(2.0 * problem.orientation_weight);
  const double centre_scale = std::sqrt(2.0 * problem.position_weight);
  for (size_t i = 0; i < problem.world_from_cam.size(); ++i) {
    if (variable[i] < 0) continue;
    Eigen::Matrix<double, 6, 1> residual;
    Eigen::Matrix<double, 6, 6> jacobian;
    PosePriorJacobian(problem.world_from_cam[i], problem.prior_world_from_cam[i], rotation_scale,
                      centre_scale, &residual, &jacobian);
    out.S.block<6, 6>(6 * variable[i], 6 * variable[i]) += jacobian.transpose() * jacobian;
  }
  return out;
}

// The gauge polish, linearized: P = I − G·F with G the 7 similarity generators of the variable
// cameras (rotation about the centroid, translation, scale) and F = (GᵀWG)⁺GᵀW the weighted fit of
// a similarity to a displacement, W the polish's weights per camera.
struct GaugeFit {
  Eigen::MatrixXd generators;  // G, 6n × 7
  Eigen::MatrixXd fit;         // F, 7 × 6n
};

GaugeFit LinearizedGaugePolish(const RayTimeLmProblem& problem, const std::vector<int>& variable,
                               int num_variable, const PoseUncertaintySettings& settings) {
  const int n = 6 * num_variable;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < variable.size(); ++i) {
    if (variable[i] >= 0) centroid += problem.world_from_cam[i].translation;
  }
  centroid /= num_variable;
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, 7);
  Eigen::VectorXd w(n);
  for (size_t i = 0; i < variable.size(); ++i) {
    const int c = variable[i];
    if (c < 0) continue;
    const Eigen::Vector3d o = problem.world_from_cam[i].translation - centroid;
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector3d axis = Eigen::Vector3d::Unit(j);
      G.block<3, 1>(6 * c, j) = axis;               // δφ = ω
      G.block<3, 1>(6 * c + 3, j) = axis.cross(o);  // δO = ω × O
      G.block<3, 1>(6 * c + 3, 3 + j) = axis;       // δO = τ
    }
    G.block<3, 1>(6 * c + 3, 6) = o;  // δO = s·O
    w.segment<3>(6 * c).setConstant(settings.gauge_orientation_weight);
    w.segment<3>(6 * c + 3).setConstant(settings.gauge_position_weight);
  }
  const Eigen::MatrixXd WG = w.asDiagonal() * G;
  GaugeFit out;
  out.fit = (G.transpose() * WG).completeOrthogonalDecomposition().solve(WG.transpose());
  out.generators = std::move(G);
  return out;
}

}  // namespace

PoseUncertaintySummary EstimatePoseUncertainty(const RayTimeLmProblem& problem,
                                               const PoseUncertaintySettings& settings) {
  const auto start = std::chrono::steady_clock::now();
  PoseUncertaintySummary summary;
  summary.cameras.resize(problem.world_from_cam.size());
  std::vector<int> variable(problem.world_from_cam.size(), -1);
  int num_variable = 0;
  for (size_t i = 0; i < variable.size(); ++i) {
    if (!problem.held[i]) variable[i] = num_variable++;
  }
  if (num_variable < 2) {
    summary.reason = "fewer than two cameras reached by residuals";
    return summary;
  }
  if (num_variable > settings.max_cameras) {
    summary.reason = std::to_string(num_variable) + " cameras, above max_cameras " +
                     std::to_string(settings.max_cameras) + " (dense covariance)";
    return summary;
  }
  for (const RayTimeLmResidual& r : problem.residuals) {
    if (r.source_observation < 0 || r.target_observation < 0) {
      summary.reason = "residuals without their observations";
      return summary;
    }
  }
  const ReducedNoiseSystem system =
      BuildReducedNoiseSystem(problem, variable, num_variable, settings.scale_px2);
  const int num_scalar = 2 * system.num_residuals;
  const int num_parameters = 6 * num_variable + system.num_ray_times;
  if (num_scalar <= num_parameters || !(system.weighted_expected > 0.0)) {
    summary.reason = "no redundancy: " + std::to_string(num_scalar) + " scalar residuals for " +
                     std::to_string(num_parameters) + " parameters";
    return summary;
  }
  summary.sigma_px_estimated = std::sqrt(
      system.weighted_squares /
      (system.weighted_expected * (1.0 - static_cast<double>(num_parameters) / num_scalar)));
  summary.sigma_px = settings.sigma_px > 0.0 ? settings.sigma_px : summary.sigma_px_estimated;

  // M, the reduced gradient's covariance per unit σ².
  const int n = 6 * num_variable;
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
  for (const CameraBlocks62& blocks : system.noise_of_observation) {
    for (const auto& [c1, b1] : blocks) {
      for (const auto& [c2, b2] : blocks) M.block<6, 6>(6 * c1, 6 * c2) += b1 * b2.transpose();
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(system.S);
  if (llt.info() != Eigen::Success) {
    summary.reason = "the reduced camera matrix is not positive definite";
    return summary;
  }
  // Cov = σ² A M Aᵀ with A = P S⁻¹ = S⁻¹ − G (F S⁻¹); only its diagonal blocks are needed.
  Eigen::MatrixXd A = llt.solve(Eigen::MatrixXd::Identity(n, n));
  const GaugeFit gauge = LinearizedGaugePolish(problem, variable, num_variable, settings);
  A -= gauge.generators * (gauge.fit * A);
  // M is block-sparse (cameras that share observations): A·M costs n·nnz(M), not n³ (the
  // 457-frame desk: most of the estimate's time when dense).
  const Eigen::SparseMatrix<double> sparse_M = M.sparseView();
  const Eigen::MatrixXd AM = A * sparse_M;
  const double variance = summary.sigma_px * summary.sigma_px;

  std::vector<double> rotations, centres;
  for (size_t i = 0; i < variable.size(); ++i) {
    const int c = variable[i];
    if (c < 0) continue;
    PoseUncertainty& u = summary.cameras[i];
    const Eigen::Matrix<double, 6, 6> covariance =
        variance * AM.middleRows<6>(6 * c) * A.middleRows<6>(6 * c).transpose();
    u.rotation_deg =
        DegreesFromRadians(std::sqrt(std::max(0.0, covariance.topLeftCorner<3, 3>().trace())));
    u.centre = std::sqrt(std::max(0.0, covariance.bottomRightCorner<3, 3>().trace()));
    rotations.push_back(u.rotation_deg);
    centres.push_back(u.centre);
  }
  summary.median_rotation_deg = Median(rotations, 0.0);
  summary.median_centre = Median(centres, 0.0);
  summary.computed = true;
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
