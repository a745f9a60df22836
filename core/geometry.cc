#include "core/geometry.h"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/error.h"

namespace raytime {

Eigen::Matrix<double, 3, 4> Rigid3::Matrix3x4() const {
  Eigen::Matrix<double, 3, 4> m;
  m.leftCols<3>() = RotationMatrix();
  m.col(3) = translation;
  return m;
}

Rigid3 Sim3::TransformPose(const Rigid3& world_from_cam) const {
  return Rigid3((rotation * world_from_cam.rotation).normalized(),
                (*this) * world_from_cam.translation);
}

Sim3 Sim3::Inverse() const {
  Sim3 inv;
  inv.scale = 1.0 / scale;
  inv.rotation = rotation.conjugate();
  inv.translation = -(inv.scale * (inv.rotation * translation));
  return inv;
}

Eigen::Matrix3d Orthonormalize(const Eigen::Matrix3d& m) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

std::string RotationMatrixProblem(const Eigen::Matrix3d& m) {
  if (!m.allFinite()) return "the rotation matrix has a value that is not finite";
  const double determinant = m.determinant();
  const double off = (m.transpose() * m - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off <= kRotationMatrixTolerance && determinant > 0) return "";
  char buffer[200];
  if (!(determinant > 0)) {
    std::snprintf(buffer, sizeof(buffer),
                  "the rotation matrix has determinant %.3g, not +1 (a reflection or a singular "
                  "matrix, not a rotation)",
                  determinant);
  } else {
    std::snprintf(buffer, sizeof(buffer),
                  "the rotation matrix is not orthonormal: |RᵀR - I| reaches %.3g (tolerance %g; "
                  "a scaled or sheared matrix, not a rotation)",
                  off, kRotationMatrixTolerance);
  }
  return buffer;
}

Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& omega) {
  const double angle = omega.norm();
  if (angle < 1e-12) {
    Eigen::Matrix3d w;
    w << 0, -omega.z(), omega.y(), omega.z(), 0, -omega.x(), -omega.y(), omega.x(), 0;
    return Eigen::Matrix3d::Identity() + w;
  }
  return Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
}

Eigen::Vector3d LogSO3(const Eigen::Matrix3d& rotation) {
  Eigen::Quaterniond q(rotation);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;  // shorter arc
  const double sin_half = q.vec().norm();
  if (sin_half < 1e-12) return 2.0 * q.vec();
  const double angle = 2.0 * std::atan2(sin_half, q.w());
  return q.vec() * (angle / sin_half);
}

double RotationAngle(const Eigen::Quaterniond& rotation) {
  const Eigen::Quaterniond q = rotation.normalized();
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

double RotationAngle(const Eigen::Matrix3d& rotation) {
  // sin from the skew part, cos from the trace: exact for small and for near-pi angles.
  const Eigen::Vector3d axis(rotation(2, 1) - rotation(1, 2), rotation(0, 2) - rotation(2, 0),
                             rotation(1, 0) - rotation(0, 1));
  return std::atan2(0.5 * axis.norm(), 0.5 * (rotation.trace() - 1.0));
}

double RotationDistance(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return RotationAngle(a.conjugate() * b);
}

namespace {
// Umeyama's rotation is free about the line through collinear (or coincident) points, and
// Eigen::umeyama then returns an arbitrary one instead of failing, so check the spread first. The
// singular values of the centred points are those of the 3x3 R of their QR decomposition (what
// JacobiSVD's own QR preconditioner computes); a JacobiSVD of the 3 x N matrix itself made this
// file the slowest of the build to compile.
bool Collinear(const Eigen::Matrix3Xd& points) {
  if (points.cols() < 3) return true;
  const Eigen::Matrix<double, Eigen::Dynamic, 3> centred =
      (points.colwise() - points.rowwise().mean()).transpose();
  const Eigen::HouseholderQR<Eigen::Matrix<double, Eigen::Dynamic, 3>> qr(centred);
  const Eigen::Matrix3d r = qr.matrixQR().topRows<3>().triangularView<Eigen::Upper>();
  const Eigen::Vector3d singular = Eigen::JacobiSVD<Eigen::Matrix3d>(r).singularValues();
  return !(singular(1) > 1e-9 * singular(0));
}
}  // namespace

Sim3 FitAlignment(const std::vector<Eigen::Vector3d>& source,
                  const std::vector<Eigen::Vector3d>& target, AlignmentKind kind) {
  if (source.size() != target.size()) {
    throw std::invalid_argument("FitAlignment: source and target sizes differ");
  }
  if (kind == AlignmentKind::kNone) return Sim3();
  if (source.size() < 3) {
    throw std::invalid_argument("FitAlignment: need at least 3 point pairs, got " +
                                std::to_string(source.size()));
  }
  Eigen::Matrix3Xd src(3, source.size()), dst(3, target.size());
  for (size_t i = 0; i < source.size(); ++i) {
    src.col(i) = source[i];
    dst.col(i) = target[i];
  }
  if (Collinear(src) || Collinear(dst)) {
    throw std::invalid_argument("FitAlignment: points are collinear, the rotation is undetermined");
  }
  const Eigen::Matrix4d t = Eigen::umeyama(src, dst, kind == AlignmentKind::kSim3);
  Sim3 sim;
  const Eigen::Matrix3d sr = t.topLeftCorner<3, 3>();
  sim.scale = kind == AlignmentKind::kSim3 ? std::cbrt(sr.determinant()) : 1.0;
  if (!(sim.scale > 0) || !std::isfinite(sim.scale)) {
    throw std::invalid_argument("FitAlignment: degenerate point configuration");
  }
  sim.rotation = Eigen::Quaterniond(Orthonormalize(sr / sim.scale));
  sim.translation = t.topRightCorner<3, 1>();
  return sim;
}

const std::vector<std::string>& PoseConventionNames() {
  static const std::vector<std::string> names = {"native", "inverted", "flipped_axes",
                                                 "inverted_flipped_axes"};
  return names;
}

std::string PoseConventionName(PoseConvention convention) {
  return PoseConventionNames().at(static_cast<size_t>(convention));
}

PoseConvention ParsePoseConvention(const std::string& name) {
  const auto& names = PoseConventionNames();
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) throw InputError("unknown pose convention '" + name + "'");
  return static_cast<PoseConvention>(it - names.begin());
}

Rigid3 ApplyPoseConvention(const Rigid3& world_from_cam, PoseConvention convention) {
  // F = diag(1, -1, -1) is a 180° turn about the camera's x axis: quaternion (0, 1, 0, 0).
  const Eigen::Quaterniond flip(0, 1, 0, 0);
  switch (convention) {
    case PoseConvention::kNative:
      return world_from_cam;
    case PoseConvention::kInverted:
      return world_from_cam.Inverse();
    case PoseConvention::kFlippedAxes:
      return Rigid3(world_from_cam.rotation * flip, world_from_cam.translation);
    case PoseConvention::kInvertedFlippedAxes: {
      const Rigid3 inverse = world_from_cam.Inverse();
      return Rigid3(inverse.rotation * flip, inverse.translation);
    }
  }
  throw std::logic_error("ApplyPoseConvention: unknown convention");
}

double DegreesFromRadians(double radians) { return radians * 180.0 / M_PI; }
double RadiansFromDegrees(double degrees) { return degrees * M_PI / 180.0; }

}  // namespace raytime
