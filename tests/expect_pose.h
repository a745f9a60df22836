// Pose comparison shared by the tests that read or interpolate poses.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/geometry.h"

namespace raytime {

// Rotation (radians) and centre (metres) of `actual` each within `tolerance` of `expected`.
inline void ExpectPoseNear(const Rigid3& actual, const Rigid3& expected, double tolerance,
                           const std::string& what = "") {
  EXPECT_LE(RotationDistance(actual.rotation, expected.rotation), tolerance) << what;
  EXPECT_LE((actual.translation - expected.translation).norm(), tolerance) << what;
}

// Every pose of `actual` bit-equal to `expected`'s (determinism, equivalent configurations).
inline void ExpectSamePoses(const std::vector<Rigid3>& actual, const std::vector<Rigid3>& expected,
                            const std::string& what = "") {
  ASSERT_EQ(actual.size(), expected.size()) << what;
  for (size_t i = 0; i < actual.size(); ++i) {
    EXPECT_EQ(actual[i].rotation.coeffs(), expected[i].rotation.coeffs())
        << what << ", image " << i;
    EXPECT_EQ(actual[i].translation, expected[i].translation) << what << ", image " << i;
  }
}

}  // namespace raytime
