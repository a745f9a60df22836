// The prior convention check (refine/checks/prior_convention.h, issue 30 item 2) on synthetic
// camera layouts with known poses: a correct prior, exact or perturbed up to the ladder's 32°, is
// accepted; the same prior inverted, with flipped camera axes or both is refused, the named
// repair (core/geometry.h ApplyPoseConvention) undoes the mistake, and what it repairs is
// accepted. The relative poses are the truth's with 0.3° of noise, as the front end's are.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "refine/checks/prior_convention.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

// Cameras on an arc looking at the origin (Strecha-like: small relative rotations, strong
// parallax), or, with `pan`, one spot turning (a phone panning: no parallax).
std::vector<Rigid3> ConventionTestCameras(int n, bool pan) {
  std::vector<Rigid3> cameras;
  for (int i = 0; i < n; ++i) {
    const double a = (pan ? 0.15 : 0.12) * (i - n / 2.0);
    const Eigen::Vector3d centre =
        pan ? Eigen::Vector3d(0.01 * i, 0, 0)
            : Eigen::Vector3d(10 * std::sin(a), 0.3 * i, -10 * std::cos(a));
    // Camera z towards the origin (or straight ahead, turned by `a`), y down.
    const Eigen::Vector3d z =
        pan ? Eigen::Vector3d(std::sin(a), 0.1, std::cos(a)).normalized() : (-centre).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d(0, 1, 0).cross(z).normalized();
    Eigen::Matrix3d r;
    r << x, z.cross(x), z;
    cameras.emplace_back(Eigen::Quaterniond(r), centre);
  }
  return cameras;
}

Eigen::Matrix3d ConventionTestRotation(std::mt19937* rng, double degrees) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis = DrawVector3([&] { return normal(*rng); }).normalized();
  return ExpSO3(RadiansFromDegrees(degrees) * axis);
}

// Consecutive pairs and pairs two apart, measured from `truth` with 0.3° of noise.
std::vector<MeasuredRelativePose> MeasuredFrom(const std::vector<Rigid3>& truth, bool pan) {
  std::mt19937 rng(5);
  std::vector<MeasuredRelativePose> pairs;
  for (int i = 0; i < static_cast<int>(truth.size()); ++i) {
    for (int j = i + 1; j <= i + 2 && j < static_cast<int>(truth.size()); ++j) {
      const Rigid3 cam2_from_cam1 = truth[j].Inverse() * truth[i];
      MeasuredRelativePose pair;
      pair.image1 = i;
      pair.image2 = j;
      pair.cam2_from_cam1_rotation =
          ConventionTestRotation(&rng, 0.3) * cam2_from_cam1.RotationMatrix();
      pair.cam2_from_cam1_direction =
          ConventionTestRotation(&rng, 0.3) * cam2_from_cam1.translation.normalized();
      pair.median_parallax_deg = pan ? 0.1 : 5.0;
      pairs.push_back(pair);
    }
  }
  return pairs;
}

// Each camera turned by `degrees` about a random axis and moved by 2 % of the arc's radius per
// degree, as the perturbation protocol does (paper §4.8).
std::vector<Rigid3> Perturbed(const std::vector<Rigid3>& truth, double degrees, int seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  std::vector<Rigid3> out;
  for (const Rigid3& pose : truth) {
    const Eigen::Matrix3d turn = ConventionTestRotation(&rng, degrees);
    const Eigen::Vector3d shift = 0.02 * degrees * DrawVector3([&] { return normal(rng); });
    out.emplace_back(Eigen::Quaterniond(turn * pose.RotationMatrix()), pose.translation + shift);
  }
  return out;
}

std::vector<Rigid3> Converted(const std::vector<Rigid3>& poses, PoseConvention convention) {
  std::vector<Rigid3> out;
  for (const Rigid3& pose : poses) out.push_back(ApplyPoseConvention(pose, convention));
  return out;
}

class PriorConventionTest : public ::testing::TestWithParam<bool> {};

TEST_P(PriorConventionTest, CorrectPriorsAreAcceptedUpToTheLaddersWidest) {
  const bool pan = GetParam();
  const std::vector<Rigid3> truth = ConventionTestCameras(12, pan);
  const std::vector<MeasuredRelativePose> pairs = MeasuredFrom(truth, pan);
  for (const double level : {0.0, 4.0, 16.0, 32.0}) {
    for (int seed = 0; seed < 5; ++seed) {
      const PriorConventionVerdict verdict =
          CheckPriorConvention(Perturbed(truth, level, seed), pairs);
      ASSERT_TRUE(verdict.checked);
      EXPECT_FALSE(verdict.refused)
          << "level " << level << " seed " << seed << ": " << nlohmann::json(verdict).dump();
      EXPECT_EQ(verdict.better_convention, "native");
    }
  }
  // Exact: the native score is the measurement noise.
  const PriorConventionVerdict exact = CheckPriorConvention(truth, pairs);
  EXPECT_LT(exact.scores.front().median_rotation_error_deg, 1.0);
  EXPECT_EQ(exact.num_pairs_with_parallax, pan ? 0 : exact.num_pairs);
  EXPECT_EQ(std::isnan(exact.scores.front().median_direction_error_deg), pan);
}

// The mistakes a file can hold (the truth T inverted, its camera axes flipped, or both in either
// order) and the repair that undoes each, up to a change of world frame.
struct ConventionMistake {
  const char* name;
  Rigid3 (*mistake)(const Rigid3&);
  const char* repair;
  // A pan about the world's y axis (the camera's y) reads the same relative rotations under T⁻¹·F
  // (F R_j R_iᵀ F = R_jᵀ R_i for turns about y) from one spot: a prior that no match can tell
  // from the truth, and that the solve treats as the truth in another world frame.
  bool seen_in_pan = true;
};

TEST_P(PriorConventionTest, PriorsInAnotherConventionAreRefusedWithTheRepairThatFitsThem) {
  const bool pan = GetParam();
  static const Eigen::Quaterniond kFlip(0, 1, 0, 0);  // F = diag(1, -1, -1)
  const std::vector<ConventionMistake> mistakes = {
      {"T^-1", [](const Rigid3& t) { return t.Inverse(); }, "inverted"},
      {"T F", [](const Rigid3& t) { return Rigid3(t.rotation * kFlip, t.translation); },
       "flipped_axes"},
      {"(T F)^-1",
       [](const Rigid3& t) { return Rigid3(t.rotation * kFlip, t.translation).Inverse(); },
       "inverted_flipped_axes"},
      {"T^-1 F",
       [](const Rigid3& t) {
         const Rigid3 inverse = t.Inverse();
         return Rigid3(inverse.rotation * kFlip, inverse.translation);
       },
       "inverted", false},
  };
  const std::vector<Rigid3> truth = ConventionTestCameras(12, pan);
  const std::vector<MeasuredRelativePose> pairs = MeasuredFrom(truth, pan);
  for (const ConventionMistake& m : mistakes) {
    if (pan && !m.seen_in_pan) continue;
    for (const double level : {0.0, 4.0, 8.0}) {
      std::vector<Rigid3> given;
      for (const Rigid3& pose : Perturbed(truth, level, 3)) given.push_back(m.mistake(pose));
      const PriorConventionVerdict verdict = CheckPriorConvention(given, pairs);
      EXPECT_TRUE(verdict.refused)
          << m.name << " at " << level << "°: " << nlohmann::json(verdict).dump();
      // From one spot, a repair and that repair followed by X -> X⁻¹·F read the same relative
      // rotations (the same prior in another world frame): either may be named, and either fits.
      if (!pan) {
        EXPECT_EQ(verdict.better_convention, m.repair) << m.name << " at " << level << "°";
      }
      const PriorConventionVerdict repaired = CheckPriorConvention(
          Converted(given, ParsePoseConvention(verdict.better_convention)), pairs);
      EXPECT_FALSE(repaired.refused) << m.name << " repaired: " << nlohmann::json(repaired).dump();
      EXPECT_LT(repaired.scores.front().median_rotation_error_deg, 2 * level + 1.0) << m.name;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(ArcAndPan, PriorConventionTest, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "Pan" : "Arc"; });

TEST(PriorConventionCheck, TooFewPairsIsNotChecked) {
  const std::vector<Rigid3> truth = ConventionTestCameras(3, false);
  std::vector<MeasuredRelativePose> pairs = MeasuredFrom(truth, false);
  pairs.resize(2);
  const PriorConventionVerdict verdict =
      CheckPriorConvention(Converted(truth, PoseConvention::kInverted), pairs);
  EXPECT_FALSE(verdict.checked);
  EXPECT_FALSE(verdict.refused);
}

TEST(PriorConventionCheck, TheRefusalNamesTheOptionAndTheValue) {
  const std::vector<Rigid3> truth = ConventionTestCameras(8, false);
  const PriorConventionVerdict verdict =
      CheckPriorConvention(Converted(truth, PoseConvention::kInverted), MeasuredFrom(truth, false));
  ASSERT_TRUE(verdict.refused);
  const std::string message = DescribeConventionRefusal(verdict, "prior.convention");
  EXPECT_NE(message.find("Set prior.convention=inverted"), std::string::npos) << message;
  EXPECT_NE(message.find("camera-to-world poses given where world-to-camera"), std::string::npos)
      << message;
}

TEST(PriorConventionCheck, ParallaxOfAPureRotationIsZeroAndOfATranslationIsNot) {
  const Eigen::Matrix3d rotation = ExpSO3(Eigen::Vector3d(0, 0.2, 0));
  Eigen::Matrix<double, Eigen::Dynamic, 3> rays1(3, 3), rotated(3, 3), shifted(3, 3);
  const Eigen::Vector3d points[3] = {{0, 0, 5}, {1, -1, 4}, {-2, 0.5, 6}};
  for (int k = 0; k < 3; ++k) {
    rays1.row(k) = points[k].normalized().transpose();
    rotated.row(k) = (rotation * points[k]).normalized().transpose();
    shifted.row(k) = (rotation * points[k] + Eigen::Vector3d(1, 0, 0)).normalized().transpose();
  }
  EXPECT_NEAR(MedianParallaxDeg(rotation, rays1, rotated), 0.0, 1e-9);
  // The middle of the three points' parallax angles, computed by hand from the geometry.
  const double expected = [&] {
    std::vector<double> angles;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d a = rotation * points[k], b = a + Eigen::Vector3d(1, 0, 0);
      angles.push_back(DegreesFromRadians(std::acos(a.normalized().dot(b.normalized()))));
    }
    std::sort(angles.begin(), angles.end());
    return angles[1];
  }();
  EXPECT_NEAR(MedianParallaxDeg(rotation, rays1, shifted), expected, 1e-9);
}

}  // namespace
}  // namespace raytime
