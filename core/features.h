// What the front end produces and later stages consume: keypoints and descriptors per image, and
// the matches and verified two-view geometry per image pair (stored as /features and /matches,
// docs/hdf5_schema.md).
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "core/geometry.h"

namespace raytime {

// Keypoints of one image, OpenCV pixel convention (SPEC §2).
struct ImageFeatures {
  // Rows: x, y (pixels), scale (pixels), orientation (radians).
  Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor> keypoints;
  // Rows: one descriptor per keypoint (SIFT: 128 columns, uint8 after RootSIFT quantization).
  Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> descriptors;
};

// Configuration of a verified two-view geometry, numbered as COLMAP's TwoViewGeometry so that the
// database export is a plain copy.
enum class TwoViewConfig : int {
  kUndefined = 0,
  kDegenerate = 1,
  kCalibrated = 2,
  kUncalibrated = 3,
  kPlanar = 4,
  kPanoramic = 5,
  kPlanarOrPanoramic = 6,
  kWatermark = 7,
  kMultiple = 8,
};

struct TwoViewGeometry {
  TwoViewConfig config = TwoViewConfig::kUndefined;
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  // Relative pose cam2_from_cam1 when known (identity otherwise).
  Rigid3 cam2_from_cam1;
  // Rows: keypoint index in image 1, keypoint index in image 2.
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> inlier_matches;
};

// Putative matches and the verified geometry of one image pair (image1 < image2, indices into
// the image list).
struct PairMatches {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
  TwoViewGeometry geometry;
};

}  // namespace raytime
