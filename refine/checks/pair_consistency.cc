#include "refine/checks/pair_consistency.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/statistics.h"

namespace raytime {
double PositiveRayEpipolarDistance(const IntrinsicsVector& source_intrinsics,
                                   const Rigid3& source_world_from_cam,
                                   const Eigen::Vector2d& source_pixel,
                                   const IntrinsicsVector& target_intrinsics,
                                   const Rigid3& target_world_from_cam,
                                   const Eigen::Vector2d& target_pixel) {
  const double* s = source_intrinsics.data();
  const double* k = target_intrinsics.data();
  Eigen::Vector2d target_undistorted;
  UndistortPixel(k, target_pixel.data(), target_undistorted.data());
  Eigen::Vector3d ray;
  ObservedPixelToUnitRay(s, source_pixel.data(), ray.data());
  // The ray's points in the target camera's frame are c + t e; with K the pinhole matrix, their
  // homogeneous pixels are a + t b, a = K c (the epipole), b = K e (the vanishing point), and the
  // residual's pixel is (a + t b) dehomogenized, which is what ProjectPinhole computes.
  const Eigen::Quaterniond target_from_world = target_world_from_cam.rotation.conjugate();
  const Eigen::Vector3d c =
      target_from_world * (source_world_from_cam.translation - target_world_from_cam.translation);
  const Eigen::Vector3d e = target_from_world * (source_world_from_cam.rotation * ray);
  const auto pinhole = [k](const Eigen::Vector3d& p) {
    return Eigen::Vector3d(k[kFx] * p.x() + k[kCx] * p.z(), k[kFy] * p.y() + k[kCy] * p.z(), p.z());
  };
  const Eigen::Vector3d a = pinhole(c);
  const Eigen::Vector3d b = pinhole(e);
  const Eigen::Vector3d q = target_undistorted.homogeneous();
  const auto distance_to = [&q](const Eigen::Vector3d& h) {
    return h.z() != 0.0 ? (h.hnormalized() - q.head<2>()).norm()
                        : std::numeric_limits<double>::infinity();
  };
  const Eigen::Vector3d line = a.cross(b);  // the epipolar line
  const double normal2 = line.head<2>().squaredNorm();
  if (normal2 == 0.0) {
    // a ∥ b: the ray passes through the target's centre and every t has one image, b's (or none,
    // when b lies at infinity: the ray runs in the focal plane).
    return line.z() == 0.0 ? distance_to(b) : std::numeric_limits<double>::infinity();
  }
  // The foot f of the perpendicular from q, and f = α a + β b up to scale: it is the image of
  // t = β / α, which is positive iff α and β share a sign. f × b = α (a × b) and f × a =
  // -β (a × b) give α and β times |a × b|².
  const double signed_offset = line.dot(q) / normal2;
  const Eigen::Vector3d foot(q.x() - signed_offset * line.x(), q.y() - signed_offset * line.y(),
                             1.0);
  const double alpha = foot.cross(b).dot(line);
  const double beta = -foot.cross(a).dot(line);
  if (alpha * beta > 0.0) return std::abs(signed_offset) * std::sqrt(normal2);
  return std::min(distance_to(a), distance_to(b));
}

std::vector<PairResidual> PairResidualMedians(const std::vector<IntrinsicsVector>& image_intrinsics,
                                              const std::vector<Rigid3>& world_from_cam,
                                              const Eigen::VectorXi& images,
                                              const Keypoints& pixels,
                                              const std::vector<PairObservationMatches>& pairs) {
  const auto distance2 = [&](int from, int to) {
    const double d = PositiveRayEpipolarDistance(
        image_intrinsics[images(from)], world_from_cam[images(from)], pixels.row(from).transpose(),
        image_intrinsics[images(to)], world_from_cam[images(to)], pixels.row(to).transpose());
    return std::isfinite(d) ? d * d : std::numeric_limits<double>::infinity();
  };

  std::vector<PairResidual> out;
  out.reserve(pairs.size());
  std::vector<double> values;
  for (const PairObservationMatches& pair : pairs) {
    values.clear();
    for (Eigen::Index m = 0; m < pair.observations.rows(); ++m) {
      const int a = pair.observations(m, 0);
      const int b = pair.observations(m, 1);
      values.push_back(std::sqrt(0.5 * (distance2(a, b) + distance2(b, a))));
    }
    PairResidual result;
    result.image1 = pair.image1;
    result.image2 = pair.image2;
    result.num_matches = static_cast<int>(values.size());
    result.median_px = Median(values, 0.0);
    out.push_back(result);
  }
  return out;
}

}  // namespace raytime
