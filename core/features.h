// What the front end produces and later stages consume: keypoints and descriptors per image, and
// the matches and verified two-view geometry per image pair (stored as /features and /matches,
// docs/hdf5_schema.md).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

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

// The observations of a ray-time solve and where along its ray the solve put each (SPEC §3 "Ray
// point": X = O + t·D), stored beside the pose set it solved for (/ray_times/<pose set>,
// docs/hdf5_schema.md). The 3DGS export places its initial points there without triangulating.
struct RayTimeObservations {
  std::vector<std::string> image_names;  // the solve's images
  // Rows: row of image_names, keypoint row in that image's /features.
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> observations;
  // Rows: the keypoint, pixels (OpenCV convention, distorted as observed).
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> pixels;
  // Per observation: distance from the camera centre along the unit ray, length units of the
  // pose set; NaN for an observation that owns no ray time (the anchored variant's non-anchors).
  Eigen::VectorXd ray_times;
  // The solve's used matches, as rows of `observations`.
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
};

}  // namespace raytime
