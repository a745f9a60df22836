#include "bootstrap/prior_repair.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "core/error.h"
#include "core/statistics.h"

namespace raytime {
namespace {

constexpr int kWeiszfeldIterations = 100;
constexpr double kWeiszfeldFloorRad = 1e-9;

}  // namespace

Eigen::Matrix3d MedianRotation(const std::vector<Eigen::Matrix3d>& rotations) {
  if (rotations.empty()) throw std::invalid_argument("MedianRotation: no rotations");
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& r : rotations) sum += r;
  Eigen::Matrix3d mean = Orthonormalize(sum);
  for (int it = 0; it < kWeiszfeldIterations; ++it) {
    Eigen::Vector3d numerator = Eigen::Vector3d::Zero();
    double denominator = 0.0;
    for (const auto& r : rotations) {
      const Eigen::Vector3d v = LogSO3(mean.transpose() * r);
      const double w = 1.0 / std::max(v.norm(), kWeiszfeldFloorRad);
      numerator += w * v;
      denominator += w;
    }
    const Eigen::Vector3d step = numerator / denominator;
    mean = Orthonormalize(mean * ExpSO3(step));
    if (step.norm() < 1e-12) break;
  }
  return mean;
}

Sim3 FitGaugeToPriorCentres(const std::vector<Eigen::Vector3d>& bootstrap_centres,
                            const std::vector<Eigen::Vector3d>& prior_centres) {
  return FitAlignment(bootstrap_centres, prior_centres, AlignmentKind::kSim3);
}

PoseSet RepairRotations(const PoseSet& prior, const PoseSet& bootstrap,
                        PriorRepairSummary* summary) {
  std::vector<Eigen::Matrix3d> offsets;
  for (const auto& [name, pose] : bootstrap.world_from_cam) {
    const auto it = prior.world_from_cam.find(name);
    if (it == prior.world_from_cam.end()) continue;
    offsets.push_back(it->second.RotationMatrix() * pose.RotationMatrix().transpose());
  }
  if (offsets.empty()) {
    throw InputError("rotations-only repair: the bootstrap registered none of the prior's images");
  }
  const Eigen::Matrix3d prior_from_bootstrap = MedianRotation(offsets);
  PoseSet repaired = prior;
  PriorRepairSummary s;
  s.mode = "rotations";
  std::vector<double> change;
  for (auto& [name, pose] : repaired.world_from_cam) {
    const auto it = bootstrap.world_from_cam.find(name);
    if (it == bootstrap.world_from_cam.end()) {
      ++s.num_kept_prior;
      continue;
    }
    const Eigen::Quaterniond rotation(
        Orthonormalize(prior_from_bootstrap * it->second.RotationMatrix()));
    change.push_back(DegreesFromRadians(RotationDistance(rotation, pose.rotation)));
    pose.rotation = rotation;
    ++s.num_repaired;
  }
  s.median_rotation_change_deg = FiniteUpperMedian(change);
  if (summary) *summary = s;
  return repaired;
}

PoseSet RepairIfCoarse(const PoseSet& prior, const PoseSet& bootstrap,
                       double min_rotation_change_deg, bool bootstrap_positions_supported,
                       PriorRepairSummary* summary) {
  PriorRepairSummary s;
  PoseSet repaired = RepairRotations(prior, bootstrap, &s);
  const double change_deg = s.median_rotation_change_deg;
  if (change_deg <= min_rotation_change_deg) {
    repaired = prior;
    s.mode = "none";
    s.num_kept_prior += s.num_repaired;
    s.num_repaired = 0;
  } else if (bootstrap_positions_supported) {
    repaired = ReplaceWithBootstrap(prior, bootstrap, &s);
  }
  // The rotation change is reported as measured against the prior before any repair.
  s.median_rotation_change_deg = change_deg;
  s.min_rotation_change_deg = min_rotation_change_deg;
  if (summary) *summary = s;
  return repaired;
}

PoseSet ReplaceWithBootstrap(const PoseSet& prior, const PoseSet& bootstrap,
                             PriorRepairSummary* summary) {
  std::vector<Eigen::Vector3d> source, target;
  std::vector<Eigen::Matrix3d> offsets;
  for (const auto& [name, pose] : bootstrap.world_from_cam) {
    const auto it = prior.world_from_cam.find(name);
    if (it == prior.world_from_cam.end()) continue;
    source.push_back(pose.translation);
    target.push_back(it->second.translation);
    offsets.push_back(it->second.RotationMatrix() * pose.RotationMatrix().transpose());
  }
  if (source.size() < 3) {
    throw InputError("full replacement: the bootstrap registered " + std::to_string(source.size()) +
                     " of the prior's images, the Sim(3) gauge fit needs 3");
  }
  // The gauge rotation is the median of the per-image rotation offsets, as in the rotations-only
  // repair: a coarse prior's rotations (L° each about random axes) average down to about
  // L/sqrt(N), while a rotation fitted to its centres (moved L x 1.25 % of the scene distance
  // each, 80 % at 64°) can be off by any angle. Scale and translation are then the least-squares
  // fit of the centres under that rotation; a non-positive scale (centres too noisy to say
  // anything) falls back to the full Umeyama fit.
  const Eigen::Matrix3d rotation = MedianRotation(offsets);
  Eigen::Vector3d mean_source = Eigen::Vector3d::Zero(), mean_target = Eigen::Vector3d::Zero();
  for (size_t k = 0; k < source.size(); ++k) {
    mean_source += source[k];
    mean_target += target[k];
  }
  mean_source /= static_cast<double>(source.size());
  mean_target /= static_cast<double>(source.size());
  double cross = 0.0, spread = 0.0;
  for (size_t k = 0; k < source.size(); ++k) {
    const Eigen::Vector3d rotated = rotation * (source[k] - mean_source);
    cross += rotated.dot(target[k] - mean_target);
    spread += rotated.squaredNorm();
  }
  Sim3 prior_from_bootstrap;
  if (spread > 0.0 && cross > 0.0) {
    prior_from_bootstrap.rotation = Eigen::Quaterniond(rotation);
    prior_from_bootstrap.scale = cross / spread;
    prior_from_bootstrap.translation =
        mean_target - prior_from_bootstrap.scale * (rotation * mean_source);
  } else {
    prior_from_bootstrap = FitGaugeToPriorCentres(source, target);
  }
  PoseSet replaced = prior;
  PriorRepairSummary s;
  s.mode = "replace";
  s.scale = prior_from_bootstrap.scale;
  std::vector<double> change;
  for (auto& [name, pose] : replaced.world_from_cam) {
    const auto it = bootstrap.world_from_cam.find(name);
    if (it == bootstrap.world_from_cam.end()) {
      ++s.num_kept_prior;
      continue;
    }
    const Rigid3 mapped = prior_from_bootstrap.TransformPose(it->second);
    change.push_back(DegreesFromRadians(RotationDistance(mapped.rotation, pose.rotation)));
    pose = mapped;
    ++s.num_repaired;
  }
  s.median_rotation_change_deg = FiniteUpperMedian(change);
  if (summary) *summary = s;
  return replaced;
}

}  // namespace raytime
