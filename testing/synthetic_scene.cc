#include "testing/synthetic_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "core/camera.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

// Written-out distributions (not <random>'s, which differ between standard libraries).
class Random {
 public:
  explicit Random(uint64_t seed) : rng_(seed) {}
  double Uniform() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  double Normal() {
    const double u1 = std::max(Uniform(), 1e-300);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * Uniform());
  }
  int Below(int n) { return static_cast<int>(Uniform() * n); }

 private:
  std::mt19937_64 rng_;
};

Rigid3 LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d up(0.0, 1.0, 0.0);
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(up).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d R;
  R << x, y, z;  // columns: camera axes in world (world_from_cam)
  return Rigid3(Eigen::Quaterniond(R), centre);
}

// Distorted pixel of a world point, or false when it is behind or outside the image.
bool ProjectToKeypoint(const CameraIntrinsics& intrinsics, const Rigid3& world_from_cam,
                       const Eigen::Vector3d& point, Eigen::Vector2d* keypoint) {
  const Eigen::Vector3d p = world_from_cam.Inverse() * point;
  if (p.z() <= 0.1) return false;
  double undistorted[2];
  ProjectPinhole(intrinsics.params.data(), p.data(), undistorted);
  DistortPixel(intrinsics.params.data(), undistorted, keypoint->data());
  const double margin = 8.0;
  return keypoint->x() > margin && keypoint->y() > margin &&
         keypoint->x() < intrinsics.width - 1 - margin &&
         keypoint->y() < intrinsics.height - 1 - margin;
}

}  // namespace

CameraIntrinsics SyntheticIntrinsics(bool distortion) {
  CameraIntrinsics intrinsics;
  intrinsics.width = 1536;
  intrinsics.height = 1024;
  intrinsics.params = {1400.0, 1396.0, 770.5, 509.0, 0.0, 0.0, 0.0, 0.0};
  if (distortion) {
    intrinsics.params[kK1] = -0.12;
    intrinsics.params[kK2] = 0.03;
    intrinsics.params[kP1] = 3e-4;
    intrinsics.params[kP2] = -2e-4;
  }
  return intrinsics;
}

SyntheticSceneOptions ArcScene(int cameras, int points, double noise_px, double outliers,
                               uint64_t seed) {
  SyntheticSceneOptions options;
  options.num_cameras = cameras;
  options.num_points = points;
  options.pixel_noise = noise_px;
  options.outlier_fraction = outliers;
  options.max_pair_gap = 3;
  options.seed = seed;
  return options;
}

SyntheticScene MakeSyntheticScene(const SyntheticSceneOptions& options) {
  Random random(options.seed);
  SyntheticScene scene;
  RefineInput& input = scene.input;
  const int n = options.num_cameras;
  const CameraIntrinsics shared = SyntheticIntrinsics(options.distortion);
  if (options.focal_drift == 0.0 && options.principal_point_drift_px == 0.0) {
    input.cameras = {shared};
    input.camera_index.assign(n, 0);
  } else {
    Random drift(options.seed ^ 0x5eed1a7e5ull);
    for (int i = 0; i < n; ++i) {
      CameraIntrinsics camera = shared;
      const double focal_scale = 1.0 + options.focal_drift * drift.Uniform(-1, 1);
      camera.params[kFx] *= focal_scale;
      camera.params[kFy] *= focal_scale;
      camera.params[kCx] += options.principal_point_drift_px * drift.Uniform(-1, 1);
      camera.params[kCy] += options.principal_point_drift_px * drift.Uniform(-1, 1);
      input.cameras.push_back(camera);
      input.camera_index.push_back(i);
    }
  }

  for (int p = 0; p < options.num_points; ++p) {
    Eigen::Vector3d point;
    do {
      point = DrawVector3([&] { return random.Uniform(-1, 1); });
    } while (point.squaredNorm() > 1.0);
    scene.points.push_back(options.point_radius_m * point);
  }

  const double span = options.arc_span_deg * M_PI / 180.0;
  for (int i = 0; i < n; ++i) {
    const double angle = n > 1 ? -0.5 * span + span * i / (n - 1) : 0.0;
    const Eigen::Vector3d centre(options.arc_radius_m * std::sin(angle), random.Uniform(-1.0, 1.0),
                                 -options.arc_radius_m * std::cos(angle));
    const Eigen::Vector3d target = DrawVector3([&] { return random.Uniform(-1, 1); });
    scene.ground_truth.push_back(LookAt(centre, target));
  }
  input.prior_world_from_cam = scene.ground_truth;

  scene.keypoint_of_point.assign(n, std::vector<int>(options.num_points, -1));
  input.keypoints.resize(n);
  for (int i = 0; i < n; ++i) {
    std::vector<std::pair<int, Eigen::Vector2d>> visible;
    for (int p = 0; p < options.num_points; ++p) {
      Eigen::Vector2d keypoint;
      if (!ProjectToKeypoint(input.CameraOf(i), scene.ground_truth[i], scene.points[p],
                             &keypoint)) {
        continue;
      }
      keypoint += options.pixel_noise * DrawVector2([&] { return random.Normal(); });
      visible.emplace_back(p, keypoint);
    }
    // Keypoint order unrelated to point order, as from a detector.
    for (size_t k = visible.size(); k > 1; --k) {
      std::swap(visible[k - 1], visible[random.Below(static_cast<int>(k))]);
    }
    input.keypoints[i].resize(static_cast<Eigen::Index>(visible.size()), 2);
    for (size_t k = 0; k < visible.size(); ++k) {
      input.keypoints[i].row(static_cast<Eigen::Index>(k)) = visible[k].second.transpose();
      scene.keypoint_of_point[i][visible[k].first] = static_cast<int>(k);
    }
  }

  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (options.max_pair_gap > 0 && j - i > options.max_pair_gap) continue;
      std::vector<std::pair<uint32_t, uint32_t>> rows;
      for (int p = 0; p < options.num_points; ++p) {
        const int k = scene.keypoint_of_point[i][p];
        const int l = scene.keypoint_of_point[j][p];
        if (k >= 0 && l >= 0) rows.emplace_back(k, l);
      }
      if (rows.empty()) continue;
      const int num_keypoints_j = static_cast<int>(input.keypoints[j].rows());
      for (auto& row : rows) {
        if (random.Uniform() < options.outlier_fraction) row.second = random.Below(num_keypoints_j);
      }
      input.pairs.push_back(MakePairMatches(i, j, rows));
    }
  }
  return scene;
}

PairMatchIndices MakePairMatches(int image1, int image2,
                                 const std::vector<std::pair<uint32_t, uint32_t>>& rows) {
  PairMatchIndices pair;
  pair.image1 = image1;
  pair.image2 = image2;
  pair.matches.resize(static_cast<Eigen::Index>(rows.size()), 2);
  for (size_t m = 0; m < rows.size(); ++m) {
    pair.matches(static_cast<Eigen::Index>(m), 0) = rows[m].first;
    pair.matches(static_cast<Eigen::Index>(m), 1) = rows[m].second;
  }
  return pair;
}

void ReprojectCamera(SyntheticScene* scene, int camera, const Rigid3& world_from_cam) {
  const CameraIntrinsics& intrinsics = scene->input.CameraOf(camera);
  for (size_t p = 0; p < scene->points.size(); ++p) {
    const int k = scene->keypoint_of_point[camera][p];
    if (k < 0) continue;
    const Eigen::Vector3d c = world_from_cam.Inverse() * scene->points[p];
    double undistorted[2], distorted[2];
    ProjectPinhole(intrinsics.params.data(), c.data(), undistorted);
    DistortPixel(intrinsics.params.data(), undistorted, distorted);
    scene->input.keypoints[camera](k, 0) = distorted[0];
    scene->input.keypoints[camera](k, 1) = distorted[1];
  }
}

PoseSet ToPoseSet(const std::vector<Rigid3>& world_from_cam) {
  PoseSet poses;
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%04zu.jpg", i);
    poses.world_from_cam[name] = world_from_cam[i];
  }
  return poses;
}

std::vector<Rigid3> FromPoseSet(const PoseSet& poses, int num_cameras) {
  std::vector<Rigid3> out(num_cameras);
  for (int i = 0; i < num_cameras; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%04d.jpg", i);
    out[i] = poses.world_from_cam.at(name);
  }
  return out;
}

}  // namespace raytime
