// Tests of the shared camera model (core/camera.h): the Newton undistortion of SPEC §3 / paper
// §3.2 must invert the OpenCV distortion to far below keypoint noise over the whole image, and its
// jet derivatives must be those of the true inverse, since the refiner differentiates through it
// for self-calibration (SPEC §3 "Self-calibration") and the evaluation cache.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <array>
#include <cmath>
#include <vector>

#include "core/camera.h"
#include "tests/numeric_jacobian.h"

namespace raytime {
namespace {

constexpr int kWidth = 1536;  // the shared Strecha scenes (SPEC §8)
constexpr int kHeight = 1024;

// 8 intrinsics + 2 pixel coordinates.
constexpr int kNumDerivs = kNumIntrinsics + 2;
using Jet = ceres::Jet<double, kNumDerivs>;
using Intrinsics = std::array<double, kNumIntrinsics>;

struct NamedIntrinsics {
  const char* name;
  Intrinsics params;
};

// Realistic coefficient sets at f ~ 1400 px, principal point near the image centre.
std::vector<NamedIntrinsics> CoefficientSets() {
  return {
      {"none", {1400.0, 1400.0, 767.5, 511.5, 0.0, 0.0, 0.0, 0.0}},
      {"mild_barrel", {1400.0, 1398.0, 770.2, 509.8, -0.12, 0.03, 3e-4, -2e-4}},
      {"strong_barrel", {1380.0, 1385.0, 765.0, 514.0, -0.3, 0.1, 0.0, 0.0}},
      {"pincushion_tangential", {1420.0, 1415.0, 760.0, 505.0, 0.08, -0.01, -5e-4, 8e-4}},
  };
}

// Pixels on a grid covering the whole image, corners and borders included.
std::vector<std::array<double, 2>> ImageGrid(int step) {
  std::vector<std::array<double, 2>> pixels;
  for (int y = 0;; y += step) {
    const double v = std::min(y, kHeight - 1);
    for (int x = 0;; x += step) {
      const double u = std::min(x, kWidth - 1);
      pixels.push_back({u, v});
      if (x >= kWidth - 1) break;
    }
    if (y >= kHeight - 1) break;
  }
  return pixels;
}

TEST(CameraTest, UndistortInvertsDistortOverTheImage) {
  for (const auto& set : CoefficientSets()) {
    SCOPED_TRACE(set.name);
    double worst = 0.0;
    for (const auto& u : ImageGrid(16)) {
      double ud[2], back[2];
      DistortPixel(set.params.data(), u.data(), ud);
      UndistortPixel(set.params.data(), ud, back);
      worst = std::max({worst, std::abs(back[0] - u[0]), std::abs(back[1] - u[1])});
    }
    EXPECT_LT(worst, 1e-8) << "undistort(distort(u)) - u, pixels";
  }
}

// The refiner sees observed (distorted) pixels, so the grid of observations must invert too.
TEST(CameraTest, DistortInvertsUndistortOverTheImage) {
  for (const auto& set : CoefficientSets()) {
    SCOPED_TRACE(set.name);
    double worst = 0.0;
    for (const auto& ud : ImageGrid(16)) {
      double u[2], back[2];
      UndistortPixel(set.params.data(), ud.data(), u);
      DistortPixel(set.params.data(), u, back);
      worst = std::max({worst, std::abs(back[0] - ud[0]), std::abs(back[1] - ud[1])});
    }
    EXPECT_LT(worst, 1e-8) << "distort(undistort(u_d)) - u_d, pixels";
  }
}

TEST(CameraTest, ZeroDistortionIsIdentity) {
  const Intrinsics params = CoefficientSets()[0].params;
  for (const auto& ud : ImageGrid(64)) {
    double u[2];
    UndistortPixel(params.data(), ud.data(), u);
    // Only the normalize/denormalize round trip rounds (~1e-13 px).
    EXPECT_NEAR(u[0], ud[0], 1e-12);
    EXPECT_NEAR(u[1], ud[1], 1e-12);
  }
}

// Jacobian (2 x 10) of UndistortPixel w.r.t. (intrinsics, distorted pixel) by forward-mode jets.
Eigen::Matrix<double, 2, kNumDerivs> UndistortJacobianJet(const Intrinsics& params,
                                                          const std::array<double, 2>& ud,
                                                          double* u_out = nullptr) {
  Jet p[kNumIntrinsics];
  for (int i = 0; i < kNumIntrinsics; ++i) p[i] = Jet(params[i], i);
  const Jet ud_jet[2] = {Jet(ud[0], kNumIntrinsics), Jet(ud[1], kNumIntrinsics + 1)};
  Jet u[2];
  UndistortPixel(p, ud_jet, u);
  Eigen::Matrix<double, 2, kNumDerivs> jac;
  jac.row(0) = u[0].v.transpose();
  jac.row(1) = u[1].v.transpose();
  if (u_out != nullptr) {
    u_out[0] = u[0].a;
    u_out[1] = u[1].a;
  }
  return jac;
}

// Jacobian (2 x 10) of DistortPixel w.r.t. (intrinsics, undistorted pixel).
Eigen::Matrix<double, 2, kNumDerivs> DistortJacobianJet(const Intrinsics& params, const double* u) {
  Jet p[kNumIntrinsics];
  for (int i = 0; i < kNumIntrinsics; ++i) p[i] = Jet(params[i], i);
  const Jet u_jet[2] = {Jet(u[0], kNumIntrinsics), Jet(u[1], kNumIntrinsics + 1)};
  Jet ud[2];
  DistortPixel(p, u_jet, ud);
  Eigen::Matrix<double, 2, kNumDerivs> jac;
  jac.row(0) = ud[0].v.transpose();
  jac.row(1) = ud[1].v.transpose();
  return jac;
}

// The numeric Jacobian (tests/numeric_jacobian.h) in the intrinsics, then the distorted pixel.
Eigen::Matrix<double, 2, kNumDerivs> UndistortJacobianNumeric(const Intrinsics& params,
                                                              const std::array<double, 2>& ud) {
  Eigen::VectorXd x(kNumDerivs);
  for (int k = 0; k < kNumIntrinsics; ++k) x(k) = params[k];
  x(kNumIntrinsics) = ud[0];
  x(kNumIntrinsics + 1) = ud[1];
  const auto undistort = [](const Eigen::VectorXd& v) {
    Eigen::Vector2d u;
    UndistortPixel(v.data(), v.data() + kNumIntrinsics, u.data());
    return u;
  };
  return NumericJacobian(undistort, x, 1e-5);
}

TEST(CameraTest, UndistortJetDerivativesMatchCentralDifferences) {
  for (const auto& set : CoefficientSets()) {
    SCOPED_TRACE(set.name);
    for (const auto& ud : ImageGrid(128)) {
      const auto jet = UndistortJacobianJet(set.params, ud);
      const auto numeric = UndistortJacobianNumeric(set.params, ud);
      for (int r = 0; r < 2; ++r) {
        for (int k = 0; k < kNumDerivs; ++k) {
          // Relative 1e-6, with an absolute floor of 1e-6 for entries that vanish (e.g. the
          // derivative w.r.t. k1 at the principal point).
          EXPECT_NEAR(jet(r, k), numeric(r, k), 1e-6 * std::max(1.0, std::abs(numeric(r, k))))
              << "row " << r << " variable " << k << " at (" << ud[0] << ", " << ud[1] << ")";
        }
      }
    }
  }
}

// Implicit function theorem: with D(u; theta) = u_d, the undistortion's derivatives are
// du/du_d = (dD/du)^-1 and du/dtheta = -(dD/du)^-1 dD/dtheta. Fixed-count Newton only has these
// derivatives if it has converged, so this checks that 5 iterations suffice for the jets too.
TEST(CameraTest, UndistortDerivativeIsInverseOfDistortJacobian) {
  for (const auto& set : CoefficientSets()) {
    SCOPED_TRACE(set.name);
    for (const auto& ud : ImageGrid(64)) {
      double u[2];
      const auto undistort_jac = UndistortJacobianJet(set.params, ud, u);
      const auto distort_jac = DistortJacobianJet(set.params, u);
      const Eigen::Matrix2d d_du = distort_jac.rightCols<2>();
      const Eigen::Matrix2d d_du_inv = d_du.inverse();
      const Eigen::Matrix<double, 2, kNumDerivs> expected =
          (Eigen::Matrix<double, 2, kNumDerivs>()
               << -d_du_inv * distort_jac.leftCols<kNumIntrinsics>(),
           d_du_inv)
              .finished();
      for (int r = 0; r < 2; ++r) {
        for (int k = 0; k < kNumDerivs; ++k) {
          EXPECT_NEAR(undistort_jac(r, k), expected(r, k),
                      1e-9 * std::max(1.0, std::abs(expected(r, k))))
              << "row " << r << " variable " << k << " at (" << ud[0] << ", " << ud[1] << ")";
        }
      }
    }
  }
}

TEST(CameraTest, PixelToUnitRayRoundTripsThroughPinholeProjection) {
  for (const auto& set : CoefficientSets()) {
    SCOPED_TRACE(set.name);
    for (const auto& u : ImageGrid(32)) {
      double ray[3];
      PixelToUnitRay(set.params.data(), u.data(), ray);
      EXPECT_NEAR(std::sqrt(ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]), 1.0, 1e-15);
      EXPECT_GT(ray[2], 0.0);  // z forward
      // A point anywhere along the ray (SPEC §3 "Ray point") projects back to the pixel.
      for (const double t : {1.0, 0.37, 25.0}) {
        const double point[3] = {t * ray[0], t * ray[1], t * ray[2]};
        double back[2];
        ProjectPinhole(set.params.data(), point, back);
        EXPECT_NEAR(back[0], u[0], 1e-9);
        EXPECT_NEAR(back[1], u[1], 1e-9);
      }
    }
  }
}

TEST(CameraTest, IntrinsicsAccessorsAndDistortionFlag) {
  CameraIntrinsics camera;
  camera.width = kWidth;
  camera.height = kHeight;
  camera.params = CoefficientSets()[0].params;
  EXPECT_FALSE(camera.HasDistortion());
  EXPECT_EQ(camera.fx(), 1400.0);
  EXPECT_EQ(camera.cx(), 767.5);
  CameraIntrinsics other = camera;
  EXPECT_TRUE(other == camera);
  other.params[kP2] = 1e-6;
  EXPECT_TRUE(other.HasDistortion());
  EXPECT_FALSE(other == camera);
}

}  // namespace
}  // namespace raytime
