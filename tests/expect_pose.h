// Pose comparison shared by the tests that read or interpolate poses.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "core/geometry.h"

namespace raytime {

// Rotation (radians) and centre (metres) of `actual` each within `tolerance` of `expected`.
inline void ExpectPoseNear(const Rigid3& actual, const Rigid3& expected, double tolerance,
                           const std::string& what = "") {
  EXPECT_LE(RotationDistance(actual.rotation, expected.rotation), tolerance) << what;
  EXPECT_LE((actual.translation - expected.translation).norm(), tolerance) << what;
}

}  // namespace raytime
