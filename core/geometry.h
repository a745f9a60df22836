// Rigid and similarity transforms, SO(3) exp/log and the Umeyama fit (SPEC §2, §6).
//
// Naming: a transform is named by its direction, `b_from_a` maps points in frame a to frame b.
// A camera pose is `world_from_cam`: its rotation is the camera-to-world rotation R_i (columns are
// the camera axes in world) and its translation is the camera centre O_i in world coordinates.
// Quaternions are Eigen's: memory order (x, y, z, w), constructor order (w, x, y, z).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "core/named_enum.h"

namespace raytime {

struct Rigid3 {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3() = default;
  Rigid3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : rotation(q), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return rotation * x + translation; }
  Rigid3 operator*(const Rigid3& o) const {
    return Rigid3(rotation * o.rotation, rotation * o.translation + translation);
  }
  Rigid3 Inverse() const {
    const Eigen::Quaterniond inv = rotation.conjugate();
    return Rigid3(inv, -(inv * translation));
  }
  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  Eigen::Matrix<double, 3, 4> Matrix3x4() const;
};

// x_b = scale * R * x_a + t.
struct Sim3 {
  double scale = 1.0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const {
    return scale * (rotation * x) + translation;
  }
  // Applies the similarity to a camera pose world_from_cam: the centre moves as a point, the
  // orientation is rotated; scale does not enter the rotation.
  Rigid3 TransformPose(const Rigid3& world_from_cam) const;
  Sim3 Inverse() const;
};

// Nearest rotation in Frobenius norm (SVD, determinant +1). Files carry 6 decimals; an
// unprojected matrix alone reads as ~0.03° of error (SPEC §2).
Eigen::Matrix3d Orthonormalize(const Eigen::Matrix3d& m);

// How far a rotation matrix read from a file may be from SO(3): the largest entry of |MᵀM − I|.
// Files with 6 decimals are off by ~1e-6 there and float32 by ~1e-7; at 1e-3 the nearest rotation
// is ambiguous by at most ~0.06°, where a sheared or scaled matrix (one that Orthonormalize would
// quietly turn into a rotation several degrees off) is off by 1e-2 and more.
constexpr double kRotationMatrixTolerance = 1e-3;
// "" when `m` is a rotation within kRotationMatrixTolerance; otherwise what is wrong with it (not
// finite, a reflection, or how far it is from orthonormal), for a reader's error message.
std::string RotationMatrixProblem(const Eigen::Matrix3d& m);

// SO(3) exponential of a rotation vector (axis * angle, radians) and its logarithm (shorter arc).
Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& omega);
Eigen::Vector3d LogSO3(const Eigen::Matrix3d& rotation);

// Angle of a rotation in radians, via atan2 of sin and cos so small angles keep full precision
// (SPEC §6: not acos).
double RotationAngle(const Eigen::Matrix3d& rotation);
double RotationAngle(const Eigen::Quaterniond& rotation);
// Angle between two rotations, radians.
double RotationDistance(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

enum class AlignmentKind { kSim3, kSE3, kNone };
constexpr std::array<EnumName<AlignmentKind>, 3> EnumNames(AlignmentKind) {
  return {{{AlignmentKind::kSim3, "sim3"},
           {AlignmentKind::kSE3, "se3"},
           {AlignmentKind::kNone, "none"}}};
}

// Least-squares transform mapping `source` points onto `target` (Umeyama 1991). kSE3 fixes the
// scale at 1, kNone returns the identity. Requires >= 3 non-collinear points for kSim3/kSE3;
// throws std::invalid_argument otherwise.
Sim3 FitAlignment(const std::vector<Eigen::Vector3d>& source,
                  const std::vector<Eigen::Vector3d>& target, AlignmentKind kind);

// A repair of poses read in the wrong convention, the field's most common mistake (issue 30),
// applied to each pose X = world_from_cam as a reader returned it: kInverted gives X⁻¹
// (camera-to-world given where world-to-camera was expected, or the reverse), kFlippedAxes X·F with
// F = diag(1, -1, -1) (OpenGL camera axes where OpenCV's were expected, or the reverse),
// kInvertedFlippedAxes X⁻¹·F (both). Up to a change of world frame, which no relative pose sees,
// these four cover the mistakes: a file holding T⁻¹·F is repaired by kInverted (F·T), one holding
// (T·F)⁻¹ by kInvertedFlippedAxes.
enum class PoseConvention { kNative, kInverted, kFlippedAxes, kInvertedFlippedAxes };
// "native", "inverted", "flipped_axes", "inverted_flipped_axes", in enum order.
const std::vector<std::string>& PoseConventionNames();
std::string PoseConventionName(PoseConvention convention);
// Throws std::invalid_argument for a name not in PoseConventionNames().
PoseConvention ParsePoseConvention(const std::string& name);
Rigid3 ApplyPoseConvention(const Rigid3& world_from_cam, PoseConvention convention);

double DegreesFromRadians(double radians);
double RadiansFromDegrees(double degrees);

}  // namespace raytime
