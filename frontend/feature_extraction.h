// SIFT keypoints and descriptors per image (SPEC §5, paper §4.1), with OpenCV's SIFT.
//
// Keypoints are stored in the OpenCV pixel convention (centre of the top-left pixel at (0, 0));
// OpenCV 4.6's upsampled first octave reports positions 0.25 px too far right and down (its
// upsampling maps pixel centres, its keypoint scaling does not; fixed upstream in 4.8 by
// `enable_precise_upscale`), which ExtractSift corrects.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/features.h"
#include "core/options.h"
#include "core/types.h"
#include "frontend/descriptor_matching.h"

namespace raytime {

struct FeatureExtractionOptions {
  // Keypoint locations per image, as COLMAP's SiftExtraction.max_num_features counts them:
  // whole octaves from the coarsest down until this many locations are exceeded, and a location
  // with a second dominant orientation keeps both descriptors; an image may hold more keypoints.
  int max_features = 8192;
  // Octave the scale space starts at (Lowe 2004 §3.3): -1 doubles the image first (COLMAP's
  // default and OpenCV's only mode), 0 starts at the native resolution (about 4x faster, fewer
  // small-scale keypoints), k > 0 at 2^-k of it. OpenCV always doubles, so k >= 0 is obtained by
  // downscaling the image by 2^-(k+1) (area interpolation) and scaling keypoints back.
  int first_octave = -1;
  // OpenCV's contrastThreshold: a DoG extremum is kept when its interpolated value exceeds
  // contrast_threshold / 3 (3 layers per octave) for images in [0, 1]. 0.04 is OpenCV's default;
  // 0.02 matches COLMAP's peak_threshold (0.02 / 3, VLFeat), which keeps weaker extrema.
  double contrast_threshold = 0.02;
  // Lowe's edge threshold r on the ratio of principal curvatures (OpenCV and COLMAP: 10).
  double edge_threshold = 10.0;
  // RootSIFT (Arandjelovic & Zisserman 2012): L1-normalize, square root, so the L2 distance of
  // the results is the Hellinger kernel on the originals; COLMAP's default normalization.
  bool root_sift = true;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("max_features", max_features,
      "Keypoint locations per image, counted in whole octaves as COLMAP's max_num_features",
      Positive());
    v("first_octave", first_octave,
      "Scale-space start: -1 doubles the image (COLMAP's default), 0 native, k > 0 at 2^-k",
      AtLeast(-1));
    v("contrast_threshold", contrast_threshold,
      "OpenCV SIFT contrastThreshold (0.02 ~ COLMAP's peak_threshold)", Positive());
    v("edge_threshold", edge_threshold, "Lowe's edge threshold r on principal curvatures",
      Above(1));
    v("root_sift", root_sift, "RootSIFT descriptors (COLMAP's default normalization)");
  }
};

struct FeatureExtractionSummary {
  int num_images = 0;
  int64_t num_keypoints = 0;  // over all images
  int min_keypoints = 0;      // per image
  int max_keypoints = 0;
  double seconds = 0;  // wall clock, all images

  nlohmann::json ToJson() const;  // the fields by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FeatureExtractionSummary, num_images, num_keypoints,
                                   min_keypoints, max_keypoints, seconds)

// Keypoints and descriptors of one 8-bit grayscale image. Keypoint rows: x, y (OpenCV pixel
// convention), scale = KeyPoint::size / 2 (pixels), orientation = KeyPoint::angle in radians.
// Descriptors: 128 uint8 per keypoint, 512 x the unit-length (Root)SIFT vector, saturated at
// 255 (COLMAP's quantization). Keypoints are sorted by decreasing response, then position, so the
// output does not depend on thread scheduling; the budget is
// FeatureExtractionOptions::max_features.
ImageFeatures ExtractSift(const cv::Mat& gray, const FeatureExtractionOptions& options);

// Quantizes OpenCV's float SIFT descriptors (one per row) as described at ExtractSift.
ByteDescriptors QuantizeSiftDescriptors(const cv::Mat& descriptors, bool root_sift);

// Reads every image of `images` (image_root / name) and extracts its features, in parallel over
// images; features[i] belongs to images.images[i]. An unreadable image, or one whose size differs
// from the image list, is an InputError naming the file.
FeatureExtractionSummary ExtractFeatures(const ImageSet& images,
                                         const FeatureExtractionOptions& options,
                                         std::vector<ImageFeatures>* features);

}  // namespace raytime
