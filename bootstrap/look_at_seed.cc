#include "bootstrap/look_at_seed.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

namespace raytime {
namespace {

double RmsSpread(const std::vector<Eigen::Vector3d>& points) {
  if (points.empty()) return 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  double sum = 0.0;
  for (const auto& p : points) sum += (p - centroid).squaredNorm();
  return std::sqrt(sum / static_cast<double>(points.size()));
}

}  // namespace

LookAtSeedResult LookAtSeed(const std::vector<Eigen::Matrix3d>& world_from_cam,
                            const LookAtSeedOptions& options) {
  ValidateOptions(options, "look-at seed");
  LookAtSeedResult result;
  Eigen::Vector3d mean_axis = Eigen::Vector3d::Zero();
  for (const auto& rotation : world_from_cam) {
    if (!rotation.allFinite()) throw std::invalid_argument("LookAtSeed: non-finite rotation");
    const Eigen::Vector3d axis = rotation.col(2);  // optical axis in world
    result.centres.push_back(-options.look_at_distance * axis);
    mean_axis += axis;
  }
  const double base_spread = RmsSpread(result.centres);
  const double min_spread = options.look_at_min_spread * options.look_at_distance;
  if (result.centres.size() >= 2 && base_spread < min_spread) {
    // A ring of radius r has RMS spread r about its centre, so adding one of radius
    // min_spread + base_spread keeps the total spread >= min_spread (triangle inequality).
    const Eigen::Vector3d a = mean_axis.norm() > 1e-9 ? Eigen::Vector3d(mean_axis.normalized())
                                                      : Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d u = a.unitOrthogonal();
    const Eigen::Vector3d v = a.cross(u);
    const double radius = min_spread + base_spread;
    const double n = static_cast<double>(result.centres.size());
    for (size_t k = 0; k < result.centres.size(); ++k) {
      const double theta = 2.0 * M_PI * static_cast<double>(k) / n;
      result.centres[k] += radius * (std::cos(theta) * u + std::sin(theta) * v);
    }
    result.spread_fallback = true;
  }
  result.spread = RmsSpread(result.centres);
  return result;
}

}  // namespace raytime
