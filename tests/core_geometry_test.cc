// Tests of core/geometry: SO(3) exp/log, the atan2 rotation angle (SPEC §6: not acos), the
// orthonormalization of 6-decimal file rotations (SPEC §2) and the Umeyama alignment used by the
// evaluation (SPEC §6, paper §4.1).
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "core/geometry.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

Eigen::Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  Eigen::Vector3d v;
  do {
    v = DrawVector3([&] { return normal(rng); });
  } while (v.norm() < 1e-3);
  return v.normalized();
}

Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> angle(0.0, M_PI);
  const Eigen::Vector3d axis = RandomUnit(rng);
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle(rng), axis));
}

double MaxAbs(const Eigen::MatrixXd& m) { return m.cwiseAbs().maxCoeff(); }

TEST(GeometryTest, ExpLogRoundTripGenericAngles) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> angle(1e-3, M_PI - 1e-3);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    const Eigen::Vector3d omega = angle(rng) * axis;
    const Eigen::Matrix3d r = ExpSO3(omega);
    EXPECT_LT(MaxAbs(r.transpose() * r - Eigen::Matrix3d::Identity()), 1e-14);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-14);
    EXPECT_LT((LogSO3(r) - omega).norm(), 1e-12 * omega.norm());
  }
}

TEST(GeometryTest, ExpLogSmallAngles) {
  std::mt19937_64 rng(2);
  for (const double angle : {1e-10, 1e-13, 1e-16}) {
    const Eigen::Vector3d omega = angle * RandomUnit(rng);
    const Eigen::Matrix3d r = ExpSO3(omega);
    // Relative precision survives: the angle is not lost to the 1 on the diagonal.
    EXPECT_LT((LogSO3(r) - omega).norm(), 1e-9 * angle) << "angle " << angle;
    EXPECT_NEAR(RotationAngle(r), angle, 1e-9 * angle);
  }
  EXPECT_EQ(LogSO3(Eigen::Matrix3d::Identity()), Eigen::Vector3d::Zero());
  EXPECT_EQ(ExpSO3(Eigen::Vector3d::Zero()), Eigen::Matrix3d::Identity());
}

TEST(GeometryTest, ExpLogNearPi) {
  std::mt19937_64 rng(3);
  for (const double gap : {1e-3, 1e-6, 1e-9, 0.0}) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    const Eigen::Vector3d omega = (M_PI - gap) * axis;
    const Eigen::Matrix3d r = ExpSO3(omega);
    const Eigen::Vector3d log = LogSO3(r);
    EXPECT_NEAR(log.norm(), M_PI - gap, 1e-12) << "gap " << gap;
    EXPECT_LT(MaxAbs(ExpSO3(log) - r), 1e-14) << "gap " << gap;
    if (gap > 0) {
      EXPECT_LT((log - omega).norm(), 1e-12) << "gap " << gap;
    } else {
      // At exactly pi the axis sign is ambiguous.
      EXPECT_NEAR(std::abs(log.normalized().dot(axis)), 1.0, 1e-12);
    }
  }
}

TEST(GeometryTest, LogReturnsTheShorterArc) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, -2, 0.5).normalized();
  const Eigen::Vector3d log = LogSO3(ExpSO3((M_PI + 0.25) * axis));
  EXPECT_LT((log - (-(M_PI - 0.25) * axis)).norm(), 1e-12);
}

TEST(GeometryTest, RotationAngleMatrixAndQuaternionAgree) {
  std::mt19937_64 rng(4);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Quaterniond q = RandomRotation(rng);
    const double expected = Eigen::AngleAxisd(q).angle();
    EXPECT_NEAR(RotationAngle(q), expected, 1e-12);
    EXPECT_NEAR(RotationAngle(q.toRotationMatrix()), expected, 1e-12);
    // The quaternion's sign does not matter.
    EXPECT_NEAR(RotationAngle(Eigen::Quaterniond(-q.coeffs())), expected, 1e-12);
  }
  for (const double gap : {1e-4, 1e-8, 0.0}) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(M_PI - gap, RandomUnit(rng)));
    EXPECT_NEAR(RotationAngle(q), M_PI - gap, 1e-12);
    EXPECT_NEAR(RotationAngle(q.toRotationMatrix()), M_PI - gap, 1e-12);
  }
}

// acos(1 - 5e-17) loses everything below ~1e-8 rad; atan2 keeps the angle of a relative rotation
// between two generic poses to ~1e-16 absolute (SPEC §6).
TEST(GeometryTest, RotationAngleAccurateAtTinyAngles) {
  std::mt19937_64 rng(5);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Quaterniond a = RandomRotation(rng);
    const double angle = 1e-8;
    const Eigen::Quaterniond b = a * Eigen::Quaterniond(Eigen::AngleAxisd(angle, RandomUnit(rng)));
    EXPECT_NEAR(RotationDistance(a, b), angle, 1e-6 * angle);
    EXPECT_NEAR(RotationAngle(a.conjugate() * b), angle, 1e-6 * angle);
    const Eigen::Matrix3d rel = a.toRotationMatrix().transpose() * b.toRotationMatrix();
    EXPECT_NEAR(RotationAngle(rel), angle, 1e-6 * angle);
  }
}

TEST(GeometryTest, OrthonormalizeRoundedRotation) {
  std::mt19937_64 rng(6);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Matrix3d r = RandomRotation(rng).toRotationMatrix();
    // Files carry 6 decimals (SPEC §2, data README).
    const Eigen::Matrix3d rounded = (r * 1e6).array().round() / 1e6;
    const Eigen::Matrix3d o = Orthonormalize(rounded);
    EXPECT_NEAR(o.determinant(), 1.0, 1e-14);
    EXPECT_LT(MaxAbs(o.transpose() * o - Eigen::Matrix3d::Identity()), 1e-14);
    EXPECT_LT(RotationAngle(Eigen::Matrix3d(r.transpose() * o)), 1e-6);
  }
}

TEST(GeometryTest, OrthonormalizeNeverReturnsAReflection) {
  std::mt19937_64 rng(7);
  const Eigen::Matrix3d r = RandomRotation(rng).toRotationMatrix();
  Eigen::Matrix3d reflected = r;
  reflected.col(2) *= -1.0;
  const Eigen::Matrix3d o = Orthonormalize(reflected);
  EXPECT_NEAR(o.determinant(), 1.0, 1e-14);
  EXPECT_LT(MaxAbs(o.transpose() * o - Eigen::Matrix3d::Identity()), 1e-14);
}

std::vector<Eigen::Vector3d> RandomPoints(std::mt19937_64& rng, int n) {
  std::uniform_real_distribution<double> coord(-5.0, 5.0);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < n; ++i) points.push_back(DrawVector3([&] { return coord(rng); }));
  return points;
}

Sim3 MakeSim3(double scale, const Eigen::Quaterniond& rotation, const Eigen::Vector3d& t) {
  Sim3 sim;
  sim.scale = scale;
  sim.rotation = rotation;
  sim.translation = t;
  return sim;
}

TEST(GeometryTest, FitAlignmentRecoversKnownSim3) {
  std::mt19937_64 rng(8);
  for (const int n : {3, 4, 25}) {
    const std::vector<Eigen::Vector3d> source = RandomPoints(rng, n);
    const Sim3 truth = MakeSim3(2.75, RandomRotation(rng), Eigen::Vector3d(10.0, -3.0, 0.5));
    std::vector<Eigen::Vector3d> target;
    for (const auto& p : source) target.push_back(truth * p);
    const Sim3 fit = FitAlignment(source, target, AlignmentKind::kSim3);
    EXPECT_NEAR(fit.scale, truth.scale, 1e-10) << n << " points";
    EXPECT_LT(RotationDistance(fit.rotation, truth.rotation), 1e-10) << n << " points";
    EXPECT_LT((fit.translation - truth.translation).norm(), 1e-10) << n << " points";
    for (size_t i = 0; i < source.size(); ++i)
      EXPECT_LT((fit * source[i] - target[i]).norm(), 1e-10);
  }
}

TEST(GeometryTest, FitAlignmentSe3RecoversRigidMotionWithUnitScale) {
  std::mt19937_64 rng(9);
  const std::vector<Eigen::Vector3d> source = RandomPoints(rng, 10);
  const Sim3 rigid = MakeSim3(1.0, RandomRotation(rng), Eigen::Vector3d(-1.0, 2.0, 3.0));
  std::vector<Eigen::Vector3d> target, scaled_target;
  for (const auto& p : source) target.push_back(rigid * p);
  const Sim3 fit = FitAlignment(source, target, AlignmentKind::kSE3);
  EXPECT_EQ(fit.scale, 1.0);
  EXPECT_LT(RotationDistance(fit.rotation, rigid.rotation), 1e-10);
  EXPECT_LT((fit.translation - rigid.translation).norm(), 1e-10);

  // With a true scale of 3 the SE(3) fit still reports scale 1 (it must not absorb scale).
  const Sim3 similarity = MakeSim3(3.0, rigid.rotation, rigid.translation);
  for (const auto& p : source) scaled_target.push_back(similarity * p);
  EXPECT_EQ(FitAlignment(source, scaled_target, AlignmentKind::kSE3).scale, 1.0);
}

TEST(GeometryTest, FitAlignmentNoneIsIdentity) {
  std::mt19937_64 rng(10);
  const std::vector<Eigen::Vector3d> a = RandomPoints(rng, 2), b = RandomPoints(rng, 2);
  const Sim3 fit = FitAlignment(a, b, AlignmentKind::kNone);
  EXPECT_EQ(fit.scale, 1.0);
  EXPECT_EQ(fit.rotation.coeffs(), Eigen::Quaterniond::Identity().coeffs());
  EXPECT_EQ(fit.translation, Eigen::Vector3d::Zero());
}

TEST(GeometryTest, FitAlignmentRejectsDegenerateInput) {
  std::mt19937_64 rng(11);
  const std::vector<Eigen::Vector3d> two = RandomPoints(rng, 2);
  EXPECT_THROW(FitAlignment(two, two, AlignmentKind::kSim3), std::invalid_argument);
  EXPECT_THROW(FitAlignment(two, two, AlignmentKind::kSE3), std::invalid_argument);
  const std::vector<Eigen::Vector3d> three = RandomPoints(rng, 3);
  EXPECT_THROW(FitAlignment(three, two, AlignmentKind::kSim3), std::invalid_argument);
  // Collinear centres (a straight camera track) leave the rotation about the line free.
  const std::vector<Eigen::Vector3d> line = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1),
                                             Eigen::Vector3d(2, 2, 2), Eigen::Vector3d(5, 5, 5)};
  EXPECT_THROW(FitAlignment(line, line, AlignmentKind::kSim3), std::invalid_argument);
  EXPECT_THROW(FitAlignment(line, line, AlignmentKind::kSE3), std::invalid_argument);
  const std::vector<Eigen::Vector3d> same(4, Eigen::Vector3d(1, 2, 3));
  EXPECT_THROW(FitAlignment(same, same, AlignmentKind::kSim3), std::invalid_argument);
  // A track 1e-6 of its length off a line still determines the rotation (threshold 1e-9).
  std::vector<Eigen::Vector3d> nearly = line;
  nearly[2] += Eigen::Vector3d(5e-6, -5e-6, 0.0);
  EXPECT_NO_THROW(FitAlignment(nearly, nearly, AlignmentKind::kSim3));
}

TEST(GeometryTest, Rigid3InverseAndComposition) {
  std::mt19937_64 rng(12);
  const Rigid3 a_from_b(RandomRotation(rng), Eigen::Vector3d(1.0, -2.0, 0.25));
  const Rigid3 b_from_c(RandomRotation(rng), Eigen::Vector3d(-4.0, 0.5, 3.0));
  const Eigen::Vector3d x_c(0.3, 0.7, -1.1);

  const Rigid3 a_from_c = a_from_b * b_from_c;
  EXPECT_LT((a_from_c * x_c - a_from_b * (b_from_c * x_c)).norm(), 1e-14);

  const Rigid3 identity = a_from_b.Inverse() * a_from_b;
  EXPECT_LT(RotationAngle(identity.rotation), 1e-15);
  EXPECT_LT(identity.translation.norm(), 1e-14);
  EXPECT_LT((a_from_b.Inverse() * (a_from_b * x_c) - x_c).norm(), 1e-14);
  EXPECT_LT(((a_from_b * b_from_c).Inverse() * (a_from_c * x_c) - x_c).norm(), 1e-14);

  const Eigen::Matrix<double, 3, 4> m = a_from_b.Matrix3x4();
  EXPECT_LT((m.leftCols<3>() * x_c + m.col(3) - a_from_b * x_c).norm(), 1e-14);
}

TEST(GeometryTest, Sim3InverseAndPoseTransform) {
  std::mt19937_64 rng(13);
  const Sim3 sim = MakeSim3(0.4, RandomRotation(rng), Eigen::Vector3d(3.0, 1.0, -2.0));
  const Eigen::Vector3d x(1.5, -0.5, 2.0);
  EXPECT_LT((sim.Inverse() * (sim * x) - x).norm(), 1e-14);

  // A camera pose moves as a whole: its centre as a point, its orientation by the rotation only.
  const Rigid3 world_from_cam(RandomRotation(rng), Eigen::Vector3d(0.2, 0.3, 0.4));
  const Rigid3 moved = sim.TransformPose(world_from_cam);
  EXPECT_LT((moved.translation - sim * world_from_cam.translation).norm(), 1e-14);
  EXPECT_LT(RotationDistance(moved.rotation, sim.rotation * world_from_cam.rotation), 1e-15);
  EXPECT_NEAR(moved.rotation.norm(), 1.0, 1e-15);
}

TEST(GeometryTest, DegreeRadianConversions) {
  EXPECT_DOUBLE_EQ(DegreesFromRadians(M_PI), 180.0);
  EXPECT_DOUBLE_EQ(RadiansFromDegrees(90.0), M_PI / 2);
  EXPECT_DOUBLE_EQ(DegreesFromRadians(RadiansFromDegrees(37.5)), 37.5);
}

}  // namespace
}  // namespace raytime
