// Perturbation protocol (SPEC §6, paper §4.8 "Basin of convergence", data README).
//
// Conventions shared by the three modes:
// - Rotations are perturbed in the world frame, R' = Exp(axis * angle) * R (world_from_cam), so
//   the angle between R and R' is exactly `angle` (R^T R' is conjugate to Exp(axis * angle)).
//   For i.i.d. draws this is distributed like the camera-frame R * Exp(...), since a uniform axis
//   stays uniform under R, and it is the frame in which kidnap segments move rigidly.
// - Random numbers: std::mt19937_64 seeded with `seed`; draws per frame (per segment for kidnap)
//   in sorted name order: the rotation axis, then the translation direction, each uniform on the
//   sphere from two 53-bit uniforms (z in [-1, 1], azimuth). The distributions are written out
//   here rather than taken from <random>, whose distributions differ between standard libraries,
//   so a seed names the same prior everywhere.
#include "evaluate/perturbation.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "core/error.h"
#include "core/statistics.h"

namespace raytime {

namespace {

class Draws {
 public:
  explicit Draws(int seed) : rng_(static_cast<uint64_t>(static_cast<int64_t>(seed))) {}

  // Uniform in [0, 1) from the top 53 bits.
  double Uniform() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }

  // Uniform on the unit sphere (Archimedes: z is uniform on [-1, 1]).
  Eigen::Vector3d UnitVector() {
    const double z = 2.0 * Uniform() - 1.0;
    const double azimuth = 2.0 * M_PI * Uniform();
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    return Eigen::Vector3d(r * std::cos(azimuth), r * std::sin(azimuth), z).normalized();
  }

 private:
  std::mt19937_64 rng_;
};

struct Draw {
  Eigen::Vector3d axis;       // rotation axis, unit
  Eigen::Vector3d direction;  // translation direction, unit
};

std::vector<Draw> MakeDraws(int seed, size_t count) {
  Draws draws(seed);
  std::vector<Draw> out(count);
  for (Draw& d : out) {
    d.axis = draws.UnitVector();
    d.direction = draws.UnitVector();
  }
  return out;
}

Rigid3 RotateInWorld(const Rigid3& world_from_cam, const Eigen::Quaterniond& rotation) {
  return Rigid3((rotation * world_from_cam.rotation).normalized(), world_from_cam.translation);
}

// Angle of Exp(v): |v| folded onto [0, pi].
double WrappedAngle(double norm) {
  const double a = std::fmod(norm, 2.0 * M_PI);
  return a > M_PI ? 2.0 * M_PI - a : a;
}

double MeanWrappedAngle(const std::vector<double>& norms, double scale) {
  double sum = 0.0;
  for (const double n : norms) sum += WrappedAngle(scale * n);
  return sum / static_cast<double>(norms.size());
}

// Scale s with mean_i angle(Exp(s * v_i)) == level for the cumulative walk vectors v_i.
// While no |s v_i| passes pi the angle is linear in s and s = level / mean |v_i| is exact. Past
// pi the angles wrap (and only shrink), so search upward from there (up to 8x the linear scale)
// for the first crossing and bisect it to machine precision.
double RandomWalkRotationScale(const std::vector<double>& norms, double level) {
  if (level == 0.0) return 0.0;
  double mean_norm = 0.0;
  for (const double n : norms) mean_norm += n;
  mean_norm /= static_cast<double>(norms.size());
  const double linear = level / mean_norm;
  if (linear * *std::max_element(norms.begin(), norms.end()) <= M_PI) return linear;

  const double step = linear / 256.0;
  double low = linear;
  double high = linear;
  while (MeanWrappedAngle(norms, high) < level) {
    low = high;
    high += step;
    if (high > 8.0 * linear) {
      throw InputError("perturbation option 'level_deg': a random walk over " +
                       std::to_string(norms.size()) + " frames cannot reach a mean rotation of " +
                       std::to_string(DegreesFromRadians(level)) +
                       "° (per-frame angles wrap at 180°); use a lower level");
    }
  }
  for (int i = 0; i < 200 && high - low > 0; ++i) {
    const double mid = 0.5 * (low + high);
    if (mid <= low || mid >= high) break;
    if (MeanWrappedAngle(norms, mid) < level) {
      low = mid;
    } else {
      high = mid;
    }
  }
  return high;
}

PoseSet PerturbIid(const PoseSet& ground_truth, double angle, double translation, int seed) {
  const std::vector<Draw> draws = MakeDraws(seed, ground_truth.size());
  PoseSet out;
  size_t i = 0;
  for (const auto& [name, pose] : ground_truth.world_from_cam) {
    const Draw& d = draws[i++];
    Rigid3 moved = RotateInWorld(pose, Eigen::Quaterniond(Eigen::AngleAxisd(angle, d.axis)));
    moved.translation += translation * d.direction;
    out.world_from_cam.emplace(name, moved);
  }
  return out;
}

// Correlated drift (paper §4.8 controls, "per-frame random walk of equal mean magnitude"): frame
// i (name order) gets the rotation vector s_R * sum_{j<=i} axis_j and the offset
// s_t * sum_{j<=i} direction_j, with the step scales s_R, s_t chosen so that the mean over frames
// of the rotation angle and of the offset length equal the i.i.d. level and translation.
PoseSet PerturbRandomWalk(const PoseSet& ground_truth, double angle, double translation, int seed) {
  const size_t n = ground_truth.size();
  const std::vector<Draw> draws = MakeDraws(seed, n);
  std::vector<Eigen::Vector3d> rotation_walk(n), translation_walk(n);
  std::vector<double> rotation_norms(n);
  double mean_translation_norm = 0.0;
  Eigen::Vector3d rotation_sum = Eigen::Vector3d::Zero(), translation_sum = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    rotation_sum += draws[i].axis;
    translation_sum += draws[i].direction;
    rotation_walk[i] = rotation_sum;
    translation_walk[i] = translation_sum;
    rotation_norms[i] = rotation_sum.norm();
    mean_translation_norm += translation_sum.norm() / static_cast<double>(n);
  }
  // The first step has length 1, so both means are positive.
  const double rotation_scale = RandomWalkRotationScale(rotation_norms, angle);
  const double translation_scale = translation / mean_translation_norm;

  PoseSet out;
  size_t i = 0;
  for (const auto& [name, pose] : ground_truth.world_from_cam) {
    const Eigen::Vector3d omega = rotation_scale * rotation_walk[i];
    const double norm = omega.norm();
    const Eigen::Quaterniond step = norm > 0
                                        ? Eigen::Quaterniond(Eigen::AngleAxisd(norm, omega / norm))
                                        : Eigen::Quaterniond::Identity();
    Rigid3 moved = RotateInWorld(pose, step);
    moved.translation += translation_scale * translation_walk[i];
    out.world_from_cam.emplace(name, moved);
    ++i;
  }
  return out;
}

// Relocalization-style error (paper §4.8 controls): three contiguous segments in name order
// (sizes differ by at most one), each moved rigidly by one draw: rotated by exactly the level
// about its centroid, then translated by exactly the level's translation, so every frame's
// rotation error is the level and every segment centroid moves by the translation.
PoseSet PerturbKidnap(const PoseSet& ground_truth, double angle, double translation, int seed) {
  constexpr size_t kSegments = 3;
  const size_t n = ground_truth.size();
  const std::vector<Draw> draws = MakeDraws(seed, kSegments);
  std::vector<std::pair<std::string, Rigid3>> poses(ground_truth.world_from_cam.begin(),
                                                    ground_truth.world_from_cam.end());
  PoseSet out;
  for (size_t s = 0; s < kSegments; ++s) {
    const size_t begin = s * n / kSegments, end = (s + 1) * n / kSegments;
    if (begin == end) continue;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (size_t i = begin; i < end; ++i) centroid += poses[i].second.translation;
    centroid /= static_cast<double>(end - begin);
    const Eigen::Quaterniond rotation(Eigen::AngleAxisd(angle, draws[s].axis));
    for (size_t i = begin; i < end; ++i) {
      Rigid3 moved = RotateInWorld(poses[i].second, rotation);
      moved.translation = centroid + rotation * (poses[i].second.translation - centroid) +
                          translation * draws[s].direction;
      out.world_from_cam.emplace(poses[i].first, moved);
    }
  }
  return out;
}

}  // namespace

double EstimateSceneDistance(const PoseSet& poses) {
  // Least squares: minimize sum_i |(I - z_i z_i^T)(p - C_i)|^2 over p, z_i = optical axis (third
  // column of world_from_cam). Normal equations: sum_i P_i p = sum_i P_i C_i.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& [name, pose] : poses.world_from_cam) {
    const Eigen::Vector3d z = pose.rotation.normalized() * Eigen::Vector3d::UnitZ();
    const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - z * z.transpose();
    a += projector;
    b += projector * pose.translation;
  }
  // Parallel (or too few) axes have no nearest point: the system is rank deficient.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(a);
  if (poses.size() < 2 || !(eigen.eigenvalues()(0) > 1e-6 * static_cast<double>(poses.size()))) {
    throw InputError(
        "cannot estimate the camera-to-scene distance: the optical axes of the " +
        std::to_string(poses.size()) +
        " poses do not converge on a point (parallel or too few); set the perturbation option "
        "'scene_distance_m' or use translation_unit 'metres'");
  }
  const Eigen::Vector3d point = a.ldlt().solve(b);
  std::vector<double> distances;
  for (const auto& [name, pose] : poses.world_from_cam) {
    distances.push_back((pose.translation - point).norm());
  }
  return Median(distances, 0.0);
}

PoseSet PerturbPoses(const PoseSet& ground_truth, const PerturbationOptions& options,
                     PerturbationSummary* summary) {
  ValidateOptions(options, "perturbation");
  if (ground_truth.size() == 0) {
    if (summary != nullptr) *summary = PerturbationSummary();
    return PoseSet();
  }
  double scene_distance = options.scene_distance_m;
  if (options.translation_unit == "scene_fraction" && scene_distance == 0.0) {
    scene_distance = EstimateSceneDistance(ground_truth);
  }
  // Data README: the centre moves by level × translation_per_deg (× the scene distance for a
  // fraction); paper §4.8 pairs 5 mm per degree at object scale.
  const double translation = options.level_deg * options.translation_per_deg *
                             (options.translation_unit == "metres" ? 1.0 : scene_distance);
  const double angle = RadiansFromDegrees(options.level_deg);
  if (summary != nullptr) {
    summary->translation_m = translation;
    summary->scene_distance_m = scene_distance;
  }
  if (options.mode == "iid") return PerturbIid(ground_truth, angle, translation, options.seed);
  if (options.mode == "random_walk") {
    return PerturbRandomWalk(ground_truth, angle, translation, options.seed);
  }
  return PerturbKidnap(ground_truth, angle, translation, options.seed);
}

}  // namespace raytime
