// The match graph as the bootstrap sees it (SPEC §4; paper §4.8 "Refinement without an external
// prior"): one edge per verified image pair carrying its two-view relative pose. The graph
// utilities every averaging step needs (connected components, spanning trees): core/graph.h.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "core/graph.h"
#include "core/named_enum.h"

namespace raytime {

// What a pair's two-view estimate can serve. Rotation averaging uses kValid and kPureRotation
// edges; translation averaging only kValid ones, because a (near-)pure rotation leaves the
// translation direction undetermined (any t satisfies the epipolar constraint).
enum class PairStatus { kValid, kPureRotation, kTooFewInliers, kFailed };
constexpr std::array<EnumName<PairStatus>, 4> EnumNames(PairStatus) {
  return {{{PairStatus::kValid, "valid"},
           {PairStatus::kPureRotation, "pure_rotation"},
           {PairStatus::kTooFewInliers, "too_few_inliers"},
           {PairStatus::kFailed, "failed"}}};
}
inline const char* PairStatusName(PairStatus status) { return NameOf(status); }

struct ViewGraphEdge {
  int image1 = 0;  // index into the image list; image1 < image2
  int image2 = 0;
  // Relative pose cam2_from_cam1: X_cam2 = rotation * X_cam1 + s * translation for an unknown
  // s > 0. `translation` is a unit vector: the direction of camera 1's centre seen from camera 2
  // (zero for a kPureRotation pair whose rotation came from the rotation-only model).
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  int num_correspondences = 0;     // stored verified correspondences the estimate started from
  int num_inliers = 0;             // five-point inliers after the polish
  double median_parallax_deg = 0;  // median angle between ray 1 and the rotated ray 2
  PairStatus status = PairStatus::kFailed;

  bool UsableForRotation() const {
    return status == PairStatus::kValid || status == PairStatus::kPureRotation;
  }
  bool UsableForTranslation() const { return status == PairStatus::kValid; }
};

}  // namespace raytime
