#include "testing/efficiency.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <spdlog/spdlog.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <numeric>
#include <random>

#include "core/camera.h"
#include "evaluate/pose_errors.h"

namespace raytime {
namespace {

// Written-out normal draws (not <random>'s distributions, which differ between standard
// libraries).
class EfficiencyNoise {
 public:
  explicit EfficiencyNoise(uint64_t seed) : rng_(seed) {}
  double Normal() {
    const double u1 = std::max(Uniform(), 1e-300);
    const double u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }

 private:
  double Uniform() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }
  std::mt19937_64 rng_;
};

// The observed (distorted) pixel of a point in an image whose pose is the truth moved by φ (world
// side, R ← Exp(φ)·R, as refine/checks/pose_uncertainty.h) and δc (centre). With the poses in
// these coordinates the bundle adjustment started at zero solves for its own error, and the
// Jacobian at zero is the Fisher information's in the coordinates the alignment is linearized in.
struct ReprojectionAboutTruth {
  ReprojectionAboutTruth(const Rigid3& truth, const CameraIntrinsics& camera,
                         const Eigen::Vector2d& observed)
      : cam_from_world(truth.rotation.toRotationMatrix().transpose()),
        centre(truth.translation),
        observed(observed) {
    std::copy(camera.params.begin(), camera.params.begin() + 8, intrinsics.begin());
  }

  template <typename T>
  bool operator()(const T* phi, const T* delta_centre, const T* point, T* residual) const {
    const T offset[3] = {point[0] - (centre.x() + delta_centre[0]),
                         point[1] - (centre.y() + delta_centre[1]),
                         point[2] - (centre.z() + delta_centre[2])};
    const T minus_phi[3] = {-phi[0], -phi[1], -phi[2]};
    T turned[3];
    ceres::AngleAxisRotatePoint(minus_phi, offset, turned);
    T p_cam[3];
    for (int r = 0; r < 3; ++r) {
      p_cam[r] = cam_from_world(r, 0) * turned[0] + cam_from_world(r, 1) * turned[1] +
                 cam_from_world(r, 2) * turned[2];
    }
    T params[8];
    for (int k = 0; k < 8; ++k) params[k] = T(intrinsics[k]);
    T undistorted[2], distorted[2];
    ProjectPinhole(params, p_cam, undistorted);
    DistortPixel(params, undistorted, distorted);
    residual[0] = distorted[0] - observed.x();
    residual[1] = distorted[1] - observed.y();
    return true;
  }

  static ceres::CostFunction* Create(const Rigid3& truth, const CameraIntrinsics& camera,
                                     const Eigen::Vector2d& observed) {
    return new ceres::AutoDiffCostFunction<ReprojectionAboutTruth, 2, 3, 3, 3>(
        new ReprojectionAboutTruth(truth, camera, observed));
  }

  Eigen::Matrix3d cam_from_world;
  Eigen::Vector3d centre;
  std::array<double, 8> intrinsics;
  Eigen::Vector2d observed;
};

Rigid3 MovedPose(const Rigid3& truth, const double* phi, const double* delta_centre) {
  const Eigen::Vector3d p(phi[0], phi[1], phi[2]);
  Rigid3 pose = truth;
  if (p.norm() > 0) {
    pose.rotation =
        Eigen::Quaterniond(Eigen::AngleAxisd(p.norm(), p.normalized())) * truth.rotation;
  }
  pose.translation += Eigen::Vector3d(delta_centre[0], delta_centre[1], delta_centre[2]);
  return pose;
}

// The linearized Sim(3) alignment on centres (Umeyama, evaluate/pose_errors.h): the similarity
// (ω, s, t) that best moves the perturbed centres back, c_i + δc_i + ω × c_i + s c_i + t, is a
// least-squares fit, so the aligned errors are a fixed linear map of the pose perturbations
// (φ_i, δc_i): δc ↦ (I − B(BᵀB)⁻¹Bᵀ) δc and φ_i ↦ φ_i + ω. A motion of the whole solution by a
// similarity maps to zero, so the gauge drops out as it does from the measured errors.
Eigen::MatrixXd AlignedErrorMap(const std::vector<Rigid3>& truth) {
  const int n = static_cast<int>(truth.size());
  Eigen::MatrixXd B(3 * n, 7);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d& c = truth[i].translation;
    Eigen::Matrix3d minus_cross;  // ω × c = −[c]× ω
    minus_cross << 0, c.z(), -c.y(), -c.z(), 0, c.x(), c.y(), -c.x(), 0;
    B.block<3, 3>(3 * i, 0) = minus_cross;
    B.block<3, 1>(3 * i, 3) = c;
    B.block<3, 3>(3 * i, 4) = Eigen::Matrix3d::Identity();
  }
  // θ = −(BᵀB)⁻¹Bᵀ δc: the fitted similarity as a map of the stacked centre perturbations.
  const Eigen::MatrixXd fit = -(B.transpose() * B).ldlt().solve(B.transpose());
  const Eigen::MatrixXd centre_map = B * fit;
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(6 * n, 6 * n);
  for (int i = 0; i < n; ++i) {
    L.block<3, 3>(6 * i, 6 * i) = Eigen::Matrix3d::Identity();
    L.block<3, 3>(6 * i + 3, 6 * i + 3) = Eigen::Matrix3d::Identity();
    for (int j = 0; j < n; ++j) {
      L.block<3, 3>(6 * i, 6 * j + 3) += fit.block<3, 3>(0, 3 * j);
      L.block<3, 3>(6 * i + 3, 6 * j + 3) += centre_map.block<3, 3>(3 * i, 3 * j);
    }
  }
  return L;
}

// The poses' Schur complement of JᵀJ at the truth, 6 per camera (φ, δc), each track's point
// eliminated.
Eigen::MatrixXd ReducedInformation(const SyntheticScene& scene,
                                   const std::vector<SceneTrack>& tracks) {
  const int n = static_cast<int>(scene.ground_truth.size());
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(6 * n, 6 * n);
  const double zero[3] = {0.0, 0.0, 0.0};
  for (const SceneTrack& track : tracks) {
    const size_t k = track.observations.size();
    std::vector<Eigen::Matrix<double, 6, 3>> W(k);
    Eigen::Matrix3d point_information = Eigen::Matrix3d::Zero();
    for (size_t o = 0; o < k; ++o) {
      const int i = track.observations[o].first;
      const std::unique_ptr<ceres::CostFunction> cost(ReprojectionAboutTruth::Create(
          scene.ground_truth[i], scene.input.CameraOf(i), Eigen::Vector2d::Zero()));
      const double* parameters[3] = {zero, zero, track.point.data()};
      Eigen::Matrix<double, 2, 3, Eigen::RowMajor> J_phi = Eigen::Matrix<double, 2, 3>::Zero(),
                                                   J_centre = J_phi, J_point = J_phi;
      double* jacobians[3] = {J_phi.data(), J_centre.data(), J_point.data()};
      double residual[2];
      cost->Evaluate(parameters, residual, jacobians);
      Eigen::Matrix<double, 2, 6> J_pose;
      J_pose << J_phi, J_centre;
      S.block<6, 6>(6 * i, 6 * i) += J_pose.transpose() * J_pose;
      W[o] = J_pose.transpose() * J_point;
      point_information += J_point.transpose() * J_point;
    }
    const Eigen::Matrix3d point_covariance = point_information.inverse();
    for (size_t a = 0; a < k; ++a) {
      for (size_t b = 0; b < k; ++b) {
        S.block<6, 6>(6 * track.observations[a].first, 6 * track.observations[b].first) -=
            W[a] * point_covariance * W[b].transpose();
      }
    }
  }
  return 0.5 * (S + S.transpose());
}

}  // namespace

std::vector<SceneTrack> MatchedTracks(const SyntheticScene& scene) {
  const RefineInput& input = scene.input;
  std::vector<int> offset(input.keypoints.size() + 1, 0);
  for (size_t i = 0; i < input.keypoints.size(); ++i) {
    offset[i + 1] = offset[i] + static_cast<int>(input.keypoints[i].rows());
  }
  std::vector<int> parent(offset.back());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  std::vector<bool> matched(offset.back(), false);
  for (const PairMatchIndices& pair : input.pairs) {
    for (Eigen::Index m = 0; m < pair.matches.rows(); ++m) {
      const int a = offset[pair.image1] + static_cast<int>(pair.matches(m, 0));
      const int b = offset[pair.image2] + static_cast<int>(pair.matches(m, 1));
      matched[a] = matched[b] = true;
      parent[find(a)] = find(b);
    }
  }
  std::map<int, SceneTrack> by_root;
  for (size_t i = 0; i < input.keypoints.size(); ++i) {
    const std::vector<int>& map = scene.keypoint_of_point[i];
    for (size_t p = 0; p < map.size(); ++p) {
      const int k = map[p];
      if (k < 0 || !matched[offset[i] + k]) continue;
      SceneTrack& track = by_root[find(offset[i] + k)];
      track.observations.emplace_back(static_cast<int>(i), k);
      track.point = scene.points[p];
    }
  }
  std::vector<SceneTrack> tracks;
  for (auto& [root, track] : by_root) tracks.push_back(std::move(track));
  return tracks;
}

RmsPoseError CramerRaoBound(const SyntheticScene& scene, const std::vector<SceneTrack>& tracks,
                            double sigma_px) {
  const int n = static_cast<int>(scene.ground_truth.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(ReducedInformation(scene, tracks));
  const Eigen::VectorXd& values = eigen.eigenvalues();  // ascending: the gauge's 7 first
  if (values(6) > 1e-8 * values(6 * n - 1) || values(7) < 1e-8 * values(6 * n - 1)) {
    spdlog::warn(fmt::format(
        "efficiency: the gauge null space is not 7-dimensional (λ7 {:.3g}, λ8 {:.3g}, max {:.3g})",
        values(6), values(7), values(6 * n - 1)));
  }
  Eigen::VectorXd inverse = Eigen::VectorXd::Zero(6 * n);
  for (int e = 7; e < 6 * n; ++e) inverse(e) = 1.0 / values(e);
  const Eigen::MatrixXd L = AlignedErrorMap(scene.ground_truth);
  const Eigen::MatrixXd LV = L * eigen.eigenvectors();
  const Eigen::MatrixXd covariance =
      sigma_px * sigma_px * LV * inverse.asDiagonal() * LV.transpose();
  double rotation = 0.0, centre = 0.0;
  for (int i = 0; i < n; ++i) {
    rotation += covariance.block<3, 3>(6 * i, 6 * i).trace() / n;
    centre += covariance.block<3, 3>(6 * i + 3, 6 * i + 3).trace() / n;
  }
  return {std::sqrt(rotation) * 180.0 / M_PI, std::sqrt(centre)};
}

// The gauge is held by camera 0's pose and one coordinate of camera 1's centre, only to condition
// the solve: the errors are measured after Sim(3).
std::vector<Rigid3> BundleAdjustFromTruth(const SyntheticScene& scene,
                                          const std::vector<SceneTrack>& tracks,
                                          const std::vector<Keypoints>& keypoints) {
  const int n = static_cast<int>(scene.ground_truth.size());
  std::vector<std::array<double, 6>> poses(n, std::array<double, 6>{0, 0, 0, 0, 0, 0});
  std::vector<Eigen::Vector3d> points;
  for (const SceneTrack& track : tracks) points.push_back(track.point);
  ceres::Problem problem;
  for (size_t t = 0; t < tracks.size(); ++t) {
    for (const auto& [i, k] : tracks[t].observations) {
      const Eigen::Vector2d observed = keypoints[i].row(k).transpose();
      problem.AddResidualBlock(
          ReprojectionAboutTruth::Create(scene.ground_truth[i], scene.input.CameraOf(i), observed),
          nullptr, poses[i].data(), poses[i].data() + 3, points[t].data());
    }
  }
  problem.SetParameterBlockConstant(poses[0].data());
  problem.SetParameterBlockConstant(poses[0].data() + 3);
  problem.SetManifold(poses[1].data() + 3, new ceres::SubsetManifold(3, {0}));
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_SCHUR;
  options.function_tolerance = 1e-14;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-14;
  options.max_num_iterations = 50;
  options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  std::vector<Rigid3> out;
  for (int i = 0; i < n; ++i) {
    out.push_back(MovedPose(scene.ground_truth[i], poses[i].data(), poses[i].data() + 3));
  }
  return out;
}

std::vector<Keypoints> NoisyKeypoints(const std::vector<Keypoints>& keypoints, double sigma_px,
                                      uint64_t seed) {
  EfficiencyNoise noise(seed);
  std::vector<Keypoints> out = keypoints;
  for (Keypoints& image : out) {
    for (Eigen::Index k = 0; k < image.rows(); ++k) {
      image(k, 0) += sigma_px * noise.Normal();
      image(k, 1) += sigma_px * noise.Normal();
    }
  }
  return out;
}

void RmsPoseErrorSum::Add(const std::vector<Rigid3>& estimate, const std::vector<Rigid3>& truth) {
  const PoseErrorSummary errors =
      ComputePoseErrors(ToPoseSet(estimate), ToPoseSet(truth), PoseErrorOptions());
  for (const FrameError& frame : errors.frames) {
    rotation_sq_ += frame.rotation_deg * frame.rotation_deg;
    centre_sq_ += frame.centre_m * frame.centre_m;
    ++count_;
  }
}

RmsPoseError RmsPoseErrorSum::Rms() const {
  return {std::sqrt(rotation_sq_ / count_), std::sqrt(centre_sq_ / count_)};
}

}  // namespace raytime
