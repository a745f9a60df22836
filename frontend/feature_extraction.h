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
  // Keypoints (descriptors) per image, at most, on any image size: DoG levels are kept whole from
  // the coarsest down, as COLMAP's SiftExtraction.max_num_features counts them, and the level
  // that crosses the budget gives its strongest locations by DoG response (ExtractSift). A
  // location with two dominant orientations counts twice. Matching cost grows with the square of
  // this number.
  int max_features = 8192;
  // Octave the scale space starts at (Lowe 2004 §3.3): -1 doubles the image first (COLMAP's
  // default and OpenCV's only mode), 0 starts at the native resolution (about 4x faster, fewer
  // small-scale keypoints), k > 0 at 2^-k of it. OpenCV always doubles, so k >= 0 is obtained by
  // downscaling the image by 2^-(k+1) (area interpolation) and scaling keypoints back.
  int first_octave = -1;
  // first_octave -1 doubles only images whose longer side is at most this many pixels; larger
  // images start at octave 0 (0 = no limit). Doubling pays while the native pyramid does not fill
  // the budget. Measured with 8192 features (bench/feature_budget.sh and the same pipeline on
  // fountain-P11): at 1536x1024 (the shared Strecha scenes) the native pyramid holds ~4.5k
  // keypoints and doubling nearly doubles the verified inliers (90.5k vs 47.8k over 55 pairs) for
  // 5.6x the extraction time; at 1920x1440 (3D Scanner App capture, 8 images) the native pyramid
  // alone exceeds the budget and doubling adds 0.6 % inliers for 5.5x the extraction time.
  int upsample_max_size = 1600;
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
      "Keypoints per image at most: whole DoG levels from the coarsest, the last by response",
      Positive(), AtMost(1e6));
    v("first_octave", first_octave,
      "Scale-space start: -1 doubles the image (COLMAP's default), 0 native, k > 0 at 2^-k",
      AtLeast(-1), AtMost(8));
    v("upsample_max_size", upsample_max_size,
      "first_octave -1 doubles only images whose longer side is at most this (px); 0 = always",
      NonNegative(), AtMost(1e6));
    v("contrast_threshold", contrast_threshold,
      "OpenCV SIFT contrastThreshold (0.02 ~ COLMAP's peak_threshold)", Positive(), AtMost(1));
    v("edge_threshold", edge_threshold, "Lowe's edge threshold r on principal curvatures", Above(1),
      AtMost(1000));
    v("root_sift", root_sift, "RootSIFT descriptors (COLMAP's default normalization)");
  }
};

struct FeatureExtractionSummary {
  int num_images = 0;
  int num_upsampled = 0;      // images whose scale space started at octave -1
  int64_t num_keypoints = 0;  // over all images
  int min_keypoints = 0;      // per image
  int max_keypoints = 0;
  double seconds = 0;  // wall clock, all images
  // Per image: its scale space started at octave -1 (not in ToJson: num_upsampled counts them).
  std::vector<bool> upsampled;

  nlohmann::json ToJson() const;  // the fields above `upsampled` by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FeatureExtractionSummary, num_images, num_upsampled,
                                   num_keypoints, min_keypoints, max_keypoints, seconds)

// The octave the scale space of a width x height image starts at: options.first_octave, except
// that -1 becomes 0 for images larger than options.upsample_max_size.
int EffectiveFirstOctave(int width, int height, const FeatureExtractionOptions& options);

// Keypoints and descriptors of one 8-bit grayscale image. Keypoint rows: x, y (OpenCV pixel
// convention), scale = KeyPoint::size / 2 (pixels), orientation = KeyPoint::angle in radians.
// Descriptors: 128 uint8 per keypoint, 512 x the unit-length (Root)SIFT vector, saturated at
// 255 (COLMAP's quantization). Keypoints are sorted by decreasing response, then position, so the
// output does not depend on thread scheduling. At most options.max_features keypoints: DoG
// levels (octave, layer) are taken whole from the coarsest down while they fit, after COLMAP's
// per-level rule, then the strongest locations (|DoG| response) of the next level while they fit.
ImageFeatures ExtractSift(const cv::Mat& gray, const FeatureExtractionOptions& options);

// The budget's keypoints of one detection (OpenCV SIFT keypoints of one image): at most
// max_features, DoG levels (octave, layer of KeyPoint::octave) taken whole from the coarsest down
// while they fit (COLMAP's per-level rule), then the strongest locations of the next level by
// response (|DoG|) while they fit. A location (position, size, octave) with several orientations
// is kept or dropped whole. Output: by decreasing response, then position; a location's
// orientations by angle.
std::vector<cv::KeyPoint> SelectKeypoints(const std::vector<cv::KeyPoint>& detected,
                                          int max_features);

// Quantizes OpenCV's float SIFT descriptors (one per row) as described at ExtractSift.
ByteDescriptors QuantizeSiftDescriptors(const cv::Mat& descriptors, bool root_sift);

// Reads every image of `images` (image_root / name) and extracts its features, in parallel over
// images; features[i] belongs to images.images[i]. An unreadable image, or one whose size differs
// from the image list, is an InputError naming the file.
FeatureExtractionSummary ExtractFeatures(const ImageSet& images,
                                         const FeatureExtractionOptions& options,
                                         std::vector<ImageFeatures>* features);

}  // namespace raytime
