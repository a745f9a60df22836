#include "refine/pair_consistency.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "refine/ray_geometry.h"

namespace raytime {
namespace {

using PoseBlock = std::array<double, kPoseBlockSize>;

// The 7-vector the cost functors read (ray_geometry.h): quaternion x, y, z, w, then the centre.
PoseBlock ToPoseBlock(const Rigid3& world_from_cam) {
  const Eigen::Quaterniond& q = world_from_cam.rotation;
  const Eigen::Vector3d& centre = world_from_cam.translation;
  return {q.x(), q.y(), q.z(), q.w(), centre.x(), centre.y(), centre.z()};
}

// CrossProjectionAutoDiffCost's arithmetic in doubles, in the same order.
Eigen::Vector2d Residual(const double* intrinsics, const double* source_pose, double ray_time,
                         const double* source_pixel, const double* target_pose,
                         const double* target_pixel) {
  double source_undistorted[2], target_undistorted[2];
  UndistortPixel(intrinsics, source_pixel, source_undistorted);
  UndistortPixel(intrinsics, target_pixel, target_undistorted);
  double point[3];
  RayPointInWorld(intrinsics, source_pose, ray_time, source_undistorted, point);
  double projected[2];
  ProjectWorldPoint(intrinsics, target_pose, point, projected);
  return Eigen::Vector2d(projected[0] - target_undistorted[0],
                         projected[1] - target_undistorted[1]);
}

double Median(std::vector<double>* values) {
  if (values->empty()) return 0.0;
  const size_t mid = values->size() / 2;
  std::nth_element(values->begin(), values->begin() + mid, values->end());
  const double upper = (*values)[mid];
  if (values->size() % 2 == 1) return upper;
  const double lower = *std::max_element(values->begin(), values->begin() + mid);
  return 0.5 * (lower + upper);
}

}  // namespace

Eigen::Vector2d CrossProjectionResidual(const IntrinsicsVector& intrinsics,
                                        const Rigid3& source_world_from_cam, double ray_time,
                                        const Eigen::Vector2d& source_pixel,
                                        const Rigid3& target_world_from_cam,
                                        const Eigen::Vector2d& target_pixel) {
  const PoseBlock source = ToPoseBlock(source_world_from_cam);
  const PoseBlock target = ToPoseBlock(target_world_from_cam);
  return Residual(intrinsics.data(), source.data(), ray_time, source_pixel.data(), target.data(),
                  target_pixel.data());
}

std::vector<PairResidual> PairResidualMedians(
    const IntrinsicsVector& intrinsics, const std::vector<Rigid3>& world_from_cam,
    const Eigen::VectorXi& images, const Keypoints& pixels, const Eigen::VectorXi& point_source,
    const Eigen::VectorXd& point_ray_time, const std::vector<PairObservationMatches>& pairs) {
  std::vector<PoseBlock> poses;
  poses.reserve(world_from_cam.size());
  for (const Rigid3& pose : world_from_cam) poses.push_back(ToPoseBlock(pose));
  const auto residual_norm2 = [&](int from, int to) {
    const int source = point_source(from);
    const Eigen::Vector2d source_pixel = pixels.row(source).transpose();
    const Eigen::Vector2d target_pixel = pixels.row(to).transpose();
    const double norm2 =
        Residual(intrinsics.data(), poses[images(source)].data(), point_ray_time(from),
                 source_pixel.data(), poses[images(to)].data(), target_pixel.data())
            .squaredNorm();
    return std::isfinite(norm2) ? norm2 : std::numeric_limits<double>::infinity();
  };

  std::vector<PairResidual> out;
  out.reserve(pairs.size());
  std::vector<double> values;
  for (const PairObservationMatches& pair : pairs) {
    values.clear();
    for (Eigen::Index m = 0; m < pair.observations.rows(); ++m) {
      const int a = pair.observations(m, 0);
      const int b = pair.observations(m, 1);
      double sum = 0.0;
      int directions = 0;
      for (const auto& [from, to] : {std::pair<int, int>(a, b), std::pair<int, int>(b, a)}) {
        if (images(point_source(from)) == images(to)) continue;
        sum += residual_norm2(from, to);
        ++directions;
      }
      if (directions > 0) values.push_back(std::sqrt(sum / directions));
    }
    PairResidual result;
    result.image1 = pair.image1;
    result.image2 = pair.image2;
    result.num_matches = static_cast<int>(values.size());
    result.median_px = Median(&values);
    out.push_back(result);
  }
  return out;
}

}  // namespace raytime
