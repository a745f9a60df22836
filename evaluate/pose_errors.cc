#include "evaluate/pose_errors.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

#include "core/error.h"
#include "core/json_fields.h"
#include "core/statistics.h"

namespace raytime {

namespace {

double Mean(const std::vector<double>& values) {
  if (values.empty()) return 0.0;
  return std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(values.size());
}

// Median distance of the ground-truth centres from their centroid. Taken over every
// ground-truth frame, not only the ones the estimate covers, so the relative errors of different
// estimates of one scene share a denominator.
double SceneScale(const PoseSet& ground_truth) {
  if (ground_truth.size() == 0) return 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& [name, pose] : ground_truth.world_from_cam) centroid += pose.translation;
  centroid /= static_cast<double>(ground_truth.size());
  std::vector<double> distances;
  for (const auto& [name, pose] : ground_truth.world_from_cam) {
    distances.push_back((pose.translation - centroid).norm());
  }
  return Median(distances, 0.0);
}

// Angles between estimated and ground-truth relative rotations, cam_i_from_cam_j = R_i^-1 R_j,
// over the frame pairs i < j in row order, every `stride`-th when there are more than
// kMaxRelativePairs.
std::vector<double> RelativeRotationErrorsDeg(const std::vector<Eigen::Quaterniond>& estimate,
                                              const std::vector<Eigen::Quaterniond>& ground_truth) {
  const size_t n = estimate.size();
  const size_t num_pairs = n < 2 ? 0 : n * (n - 1) / 2;
  const size_t stride =
      std::max<size_t>(1, (num_pairs + kMaxRelativePairs - 1) / kMaxRelativePairs);
  std::vector<double> errors;
  errors.reserve(num_pairs / stride + 1);
  size_t index = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Quaterniond est_i = estimate[i].conjugate();
    const Eigen::Quaterniond gt_i = ground_truth[i].conjugate();
    for (size_t j = i + 1; j < n; ++j, ++index) {
      if (index % stride != 0) continue;
      errors.push_back(
          DegreesFromRadians(RotationDistance(gt_i * ground_truth[j], est_i * estimate[j])));
    }
  }
  return errors;
}

}  // namespace

double AlignmentRotationSigma(const std::vector<Eigen::Vector3d>& target_centres,
                              const std::vector<double>& residual_norms, int fitted_parameters) {
  const int n = static_cast<int>(target_centres.size());
  const int dof = 3 * n - fitted_parameters;
  double squared = 0.0;
  for (const double r : residual_norms) squared += r * r;
  if (dof <= 0 || squared == 0.0) return 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : target_centres) centroid += c;
  centroid /= n;
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& c : target_centres) {
    const Eigen::Vector3d d = c - centroid;
    inertia += d.squaredNorm() * Eigen::Matrix3d::Identity() - d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(inertia);
  const Eigen::Vector3d moments = eigen.eigenvalues();
  // Relative to the largest moment: below this the rotation about that axis is not fitted.
  if (!(moments(0) > 1e-12 * moments(2))) return std::numeric_limits<double>::infinity();
  const double trace_inverse = (1.0 / moments.array()).sum();
  return std::sqrt(squared / dof * trace_inverse);
}

AlignmentKind AlignmentKindFromName(const std::string& name) {
  AlignmentKind kind = AlignmentKind::kSim3;
  if (EnumFromName(name, &kind)) return kind;
  throw InputError("unknown alignment '" + name + "' (valid alignments: sim3, se3, none)");
}

PoseErrorSummary ComputePoseErrors(const PoseSet& estimate, const PoseSet& ground_truth,
                                   const PoseErrorOptions& options) {
  const AlignmentKind kind = AlignmentKindFromName(options.alignment);
  const NameJoin join = JoinNames(Names(estimate), Names(ground_truth));

  PoseErrorSummary summary;
  summary.alignment = NameOf(kind);
  summary.only_in_estimate = join.only_left;
  summary.only_in_ground_truth = join.only_right;
  summary.num_frames = static_cast<int>(join.both.size());

  const size_t min_frames = kind == AlignmentKind::kNone ? 1 : 3;
  if (join.both.size() < min_frames) {
    std::string message = "pose errors with alignment '" + summary.alignment + "' need at least " +
                          std::to_string(min_frames) +
                          " frame(s) common to the estimate and the ground truth, got " +
                          std::to_string(join.both.size());
    if (!join.Complete()) message += " (" + join.Describe("the estimate", "the ground truth") + ")";
    throw InputError(message);
  }

  // SPEC §6: the alignment is fitted on camera centres only, estimate -> ground truth.
  std::vector<Eigen::Vector3d> estimate_centres, gt_centres;
  std::vector<Eigen::Quaterniond> estimate_rotations, gt_rotations;
  for (const std::string& name : join.both) {
    const Rigid3& estimated = estimate.world_from_cam.at(name);
    const Rigid3& gt = ground_truth.world_from_cam.at(name);
    estimate_centres.push_back(estimated.translation);
    gt_centres.push_back(gt.translation);
    estimate_rotations.push_back(estimated.rotation);
    gt_rotations.push_back(gt.rotation);
  }
  try {
    summary.gt_from_estimate = FitAlignment(estimate_centres, gt_centres, kind);
  } catch (const std::invalid_argument& e) {
    throw InputError("cannot align the estimate to the ground truth with '" + summary.alignment +
                     "': " + e.what());
  }

  std::vector<double> rotation_deg, centre_m;
  for (const std::string& name : join.both) {
    const Rigid3& gt = ground_truth.world_from_cam.at(name);
    const Rigid3 aligned = summary.gt_from_estimate.TransformPose(estimate.world_from_cam.at(name));
    FrameError frame;
    frame.name = name;
    // Angle of R_gt^-1 R_est by atan2 (SPEC §6), exact down to ~1e-16 rad.
    frame.rotation_deg = DegreesFromRadians(RotationDistance(gt.rotation, aligned.rotation));
    frame.centre_m = (aligned.translation - gt.translation).norm();
    rotation_deg.push_back(frame.rotation_deg);
    centre_m.push_back(frame.centre_m);
    summary.frames.push_back(frame);
  }

  summary.mean_rotation_deg = Mean(rotation_deg);
  summary.median_rotation_deg = Median(rotation_deg, 0.0);
  summary.mean_centre_m = Mean(centre_m);
  summary.median_centre_m = Median(centre_m, 0.0);
  summary.scene_scale_m = SceneScale(ground_truth);
  // A single ground-truth frame (or coincident centres) has no scale; relative errors stay 0.
  if (summary.scene_scale_m > 0) {
    summary.mean_centre_relative = summary.mean_centre_m / summary.scene_scale_m;
    summary.median_centre_relative = summary.median_centre_m / summary.scene_scale_m;
  }
  const std::vector<double> relative_deg =
      RelativeRotationErrorsDeg(estimate_rotations, gt_rotations);
  summary.num_relative_pairs = static_cast<int>(relative_deg.size());
  summary.mean_relative_rotation_deg = Mean(relative_deg);
  summary.median_relative_rotation_deg = Median(relative_deg, 0.0);
  if (kind != AlignmentKind::kNone) {
    summary.alignment_rotation_sigma_deg = DegreesFromRadians(
        AlignmentRotationSigma(gt_centres, centre_m, kind == AlignmentKind::kSim3 ? 7 : 6));
  }
  // Paper §4.8: a run succeeds when its mean rotation error is below 1° (configurable).
  summary.success = summary.mean_rotation_deg < options.success_rotation_deg;
  return summary;
}

void to_json(nlohmann::json& json, const PoseErrorStatistics& statistics) {
  json = FieldsToJson(statistics);
}

void from_json(const nlohmann::json& json, PoseErrorStatistics& statistics) {
  statistics = FieldsFromJson<PoseErrorStatistics>(json);
}

nlohmann::json PoseErrorSummary::ToJson(bool with_frames) const {
  nlohmann::json out = static_cast<const PoseErrorStatistics&>(*this);
  out["alignment"] = alignment;
  if (with_frames) out["frames"] = frames;
  out["only_in_estimate"] = only_in_estimate;
  out["only_in_ground_truth"] = only_in_ground_truth;
  const Eigen::Quaterniond& q = gt_from_estimate.rotation;
  const Eigen::Vector3d& t = gt_from_estimate.translation;
  out["gt_from_estimate"] = {{"scale", gt_from_estimate.scale},
                             {"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                             {"translation", {t.x(), t.y(), t.z()}}};
  return out;
}

}  // namespace raytime
