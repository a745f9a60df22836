#include "refine/solve/similarity_retraction.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "refine/solve/ray_geometry.h"

namespace raytime {

Eigen::Matrix3d CrossMatrix(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix<double, 6, 7> SimilarityTangent(const Eigen::Vector3d& centre) {
  Eigen::Matrix<double, 6, 7> tangent = Eigen::Matrix<double, 6, 7>::Zero();
  tangent.block<3, 3>(0, 0).setIdentity();
  tangent.block<3, 3>(3, 0) = -CrossMatrix(centre);  // ω × O = -[O]× ω
  tangent.block<3, 1>(3, 3) = centre;
  tangent.block<3, 3>(3, 4).setIdentity();
  return tangent;
}
Eigen::Vector3d SimilarityPivot(const std::vector<Rigid3>& poses,
                                const std::vector<int>& variable) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int count = 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] < 0) continue;
    sum += poses[i].translation;
    ++count;
  }
  return count > 0 ? Eigen::Vector3d(sum / count) : sum;
}

Eigen::Matrix<double, 7, 1> SimilarityPart(const std::vector<Rigid3>& poses,
                                           const std::vector<int>& variable,
                                           const Eigen::VectorXd& step) {
  const Eigen::Vector3d pivot = SimilarityPivot(poses, variable);
  Eigen::Matrix<double, 7, 7> normal = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> rhs = Eigen::Matrix<double, 7, 1>::Zero();
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] < 0) continue;
    const Eigen::Matrix<double, 6, 7> tangent = SimilarityTangent(poses[i].translation - pivot);
    normal.noalias() += tangent.transpose() * tangent;
    rhs.noalias() += tangent.transpose() * step.segment<6>(6 * variable[i]);
  }
  // Fewer than three cameras, or all on one line, leave some of the 7 undetermined: the
  // minimum-norm part is still an exact similarity of the step.
  return normal.completeOrthogonalDecomposition().solve(rhs);
}

void RetractPoses(const std::vector<int>& variable, const Eigen::VectorXd& step,
                  const Eigen::Matrix<double, 7, 1>& similarity, std::vector<Rigid3>* poses) {
  const Eigen::Vector3d omega = similarity.head<3>();
  const double angle = omega.norm();
  const Eigen::Quaterniond rotation =
      angle > 0.0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle))
                  : Eigen::Quaterniond::Identity();
  const double scale = std::exp(similarity[3]);
  const Eigen::Vector3d pivot = SimilarityPivot(*poses, variable);
  for (size_t i = 0; i < poses->size(); ++i) {
    if (variable[i] < 0) continue;
    Rigid3& pose = (*poses)[i];
    const Eigen::Matrix<double, 6, 1> rest =
        step.segment<6>(6 * variable[i]) - SimilarityTangent(pose.translation - pivot) * similarity;
    const Eigen::Vector3d phi = rest.head<3>();
    const double phi_angle = phi.norm();
    if (phi_angle > 0.0) {
      pose.rotation =
          Eigen::Quaterniond(Eigen::AngleAxisd(phi_angle, phi / phi_angle)) * pose.rotation;
    }
    pose.translation += rest.tail<3>();
    pose.rotation = (rotation * pose.rotation).normalized();
    pose.translation =
        pivot + scale * (rotation * (pose.translation - pivot)) + similarity.tail<3>();
  }
}

double RetractRayTime(double ray_time, double step) {
  const double ratio = step / ray_time;
  const double retracted = ratio < 1.0 - 1.0 / kMaxRayTimeGrowth ? ray_time / (1.0 - ratio)
                                                                 : kMaxRayTimeGrowth * ray_time;
  return std::max(retracted, kRayTimeLowerBound);
}

}  // namespace raytime
