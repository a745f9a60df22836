#include "frontend/feature_extraction.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tuple>

#include "core/error.h"
#include "core/progress.h"
#include "core/timing.h"
#include "frontend/image_reading.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// OpenCV 4.6 doubles the image with centre-aligned linear interpolation (pixel u of the doubled
// image sits at (u + 0.5) / 2 - 0.5) but reports keypoints at u / 2, i.e. 0.25 px too far in x
// and y at every octave (octaves are decimated from the doubled image). Measured on a synthetic
// blob: 100.233 reported for 100.0.
constexpr double kOpenCvUpsampleShift = 0.25;

}  // namespace

nlohmann::json FeatureExtractionSummary::ToJson() const { return *this; }

ByteDescriptors QuantizeSiftDescriptors(const cv::Mat& descriptors, bool root_sift) {
  CV_Assert(descriptors.empty() || descriptors.type() == CV_32F);
  ByteDescriptors out(descriptors.rows, descriptors.cols);
  std::vector<float> unit(descriptors.cols);
  for (int r = 0; r < descriptors.rows; ++r) {
    const float* d = descriptors.ptr<float>(r);
    double norm = 0;
    if (root_sift) {
      for (int c = 0; c < descriptors.cols; ++c) norm += std::abs(d[c]);
      for (int c = 0; c < descriptors.cols; ++c) {
        unit[c] = norm > 0 ? static_cast<float>(std::sqrt(std::abs(d[c]) / norm)) : 0.0f;
      }
    } else {
      for (int c = 0; c < descriptors.cols; ++c) norm += double(d[c]) * d[c];
      norm = std::sqrt(norm);
      for (int c = 0; c < descriptors.cols; ++c) {
        unit[c] = norm > 0 ? static_cast<float>(d[c] / norm) : 0.0f;
      }
    }
    for (int c = 0; c < descriptors.cols; ++c) {
      out(r, c) = static_cast<uint8_t>(std::min(255.0f, std::round(512.0f * unit[c])));
    }
  }
  return out;
}

std::vector<cv::KeyPoint> SelectKeypoints(const std::vector<cv::KeyPoint>& detected,
                                          int max_features) {
  // The budget (FeatureExtractionOptions::max_features) bounds the keypoints kept, after
  // COLMAP's per-DoG-level rule (SiftExtractionOptions::max_num_features on the CPU): DoG levels
  // are taken whole from the coarsest down (larger-scale keypoints repeat better), but where
  // COLMAP keeps the level that crosses the budget whole (so an image may hold several times the
  // budget), that level gives only its strongest locations by DoG response, as many as fit. A
  // location with a second dominant orientation (Lowe 2004 §5; OpenCV emits one keypoint per
  // orientation with identical position, size and octave) keeps both descriptors and counts
  // twice, so the matcher never sees more than max_features rows per image.
  struct Location {
    float response, x, y, size;
    int octave, layer;
    std::vector<int> members;
  };
  std::map<std::tuple<float, float, float, int>, Location> by_location;
  for (int i = 0; i < static_cast<int>(detected.size()); ++i) {
    const cv::KeyPoint& kp = detected[i];
    Location& location = by_location[{kp.pt.x, kp.pt.y, kp.size, kp.octave}];
    if (location.members.empty()) {
      // KeyPoint::octave packs the octave as a signed byte (-1 for the doubled image) and the
      // DoG layer within it (1 to nOctaveLayers) in the next byte.
      const int octave = static_cast<int8_t>(kp.octave & 255);
      const int layer = (kp.octave >> 8) & 255;
      location = {kp.response, kp.pt.x, kp.pt.y, kp.size, octave, layer, {}};
    }
    location.response = std::max(location.response, kp.response);
    location.members.push_back(i);
  }
  std::vector<const Location*> locations;
  locations.reserve(by_location.size());
  for (const auto& entry : by_location) locations.push_back(&entry.second);
  const auto stronger = [](const Location* a, const Location* b) {
    if (a->response != b->response) return a->response > b->response;
    if (a->x != b->x) return a->x < b->x;
    if (a->y != b->y) return a->y < b->y;
    return a->size < b->size;
  };
  // Coarsest DoG level first, strongest first within it; ties broken by position so the result
  // does not depend on thread scheduling.
  std::sort(locations.begin(), locations.end(), [&](const Location* a, const Location* b) {
    if (a->octave != b->octave) return a->octave > b->octave;
    if (a->layer != b->layer) return a->layer > b->layer;
    return stronger(a, b);
  });
  size_t keep = 0;
  size_t num_keypoints = 0;
  const size_t budget = static_cast<size_t>(std::max(0, max_features));
  while (keep < locations.size() && num_keypoints + locations[keep]->members.size() <= budget) {
    num_keypoints += locations[keep]->members.size();
    ++keep;
  }
  locations.resize(keep);
  std::sort(locations.begin(), locations.end(), stronger);
  std::vector<cv::KeyPoint> keypoints;
  keypoints.reserve(num_keypoints);
  for (const Location* location : locations) {
    std::vector<int> members = location->members;
    std::sort(members.begin(), members.end(),
              [&](int i, int j) { return detected[i].angle < detected[j].angle; });
    for (int i : members) keypoints.push_back(detected[i]);
  }
  return keypoints;
}

int EffectiveFirstOctave(int width, int height, const FeatureExtractionOptions& options) {
  if (options.first_octave == -1 && options.upsample_max_size > 0 &&
      std::max(width, height) > options.upsample_max_size) {
    return 0;
  }
  return options.first_octave;
}

ImageFeatures ExtractSift(const cv::Mat& gray, const FeatureExtractionOptions& options) {
  CV_Assert(gray.type() == CV_8UC1);
  cv::Mat input = gray;
  const int first_octave = EffectiveFirstOctave(gray.cols, gray.rows, options);
  if (first_octave >= 0) {
    const double factor = std::ldexp(1.0, -(first_octave + 1));
    const int width = std::max(1, static_cast<int>(std::lround(gray.cols * factor)));
    const int height = std::max(1, static_cast<int>(std::lround(gray.rows * factor)));
    cv::resize(gray, input, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  }
  // Input pixel u maps to original pixel (u + 0.5) / s - 0.5 (centres of the area cells).
  const double sx = static_cast<double>(input.cols) / gray.cols;
  const double sy = static_cast<double>(input.rows) / gray.rows;

  // Detect everything, choose the budget's locations, then describe only the kept keypoints
  // (describing the whole detection would cost several times the budget's descriptors).
  const cv::Ptr<cv::SIFT> sift =
      cv::SIFT::create(/*nfeatures=*/0, /*nOctaveLayers=*/3, options.contrast_threshold,
                       options.edge_threshold, /*sigma=*/1.6);
  std::vector<cv::KeyPoint> detected;
  sift->detect(input, detected);

  std::vector<cv::KeyPoint> keypoints = SelectKeypoints(detected, options.max_features);
  cv::Mat descriptors;
  sift->compute(input, keypoints, descriptors);
  // compute() keeps the keypoints' order and count (it only drops none for SIFT).
  CV_Assert(descriptors.rows == static_cast<int>(keypoints.size()));
  std::vector<int> order(keypoints.size());
  std::iota(order.begin(), order.end(), 0);

  const ByteDescriptors quantized = QuantizeSiftDescriptors(descriptors, options.root_sift);
  ImageFeatures features;
  features.keypoints.resize(order.size(), 4);
  features.descriptors.resize(order.size(), sift->descriptorSize());
  for (size_t k = 0; k < order.size(); ++k) {
    const cv::KeyPoint& kp = keypoints[order[k]];
    features.keypoints(k, 0) =
        static_cast<float>((kp.pt.x - kOpenCvUpsampleShift + 0.5) / sx - 0.5);
    features.keypoints(k, 1) =
        static_cast<float>((kp.pt.y - kOpenCvUpsampleShift + 0.5) / sy - 0.5);
    features.keypoints(k, 2) = static_cast<float>(0.5 * kp.size / sx);
    features.keypoints(k, 3) = static_cast<float>(kp.angle * M_PI / 180.0);
    features.descriptors.row(k) = quantized.row(order[k]);
  }
  return features;
}

FeatureExtractionSummary ExtractFeatures(const ImageSet& images,
                                         const FeatureExtractionOptions& options,
                                         std::vector<ImageFeatures>* features) {
  ValidateOptions(options, "feature extraction");
  const auto start = std::chrono::steady_clock::now();
  const int num_images = static_cast<int>(images.images.size());
  features->assign(num_images, ImageFeatures());
  std::atomic<int> done{0};
  std::vector<char> upsampled(num_images, 0);  // char: written from several threads
  ProgressBar bar("features", num_images);
  tbb::parallel_for(0, num_images, [&](int i) {
    const auto image_start = std::chrono::steady_clock::now();
    const ImageInfo& info = images.images[i];
    const std::string path = (fs::path(images.image_root) / info.name).string();
    const cv::Mat gray = ReadImage(path, cv::IMREAD_GRAYSCALE);
    if ((info.width > 0 && gray.cols != info.width) ||
        (info.height > 0 && gray.rows != info.height)) {
      ThrowInput(path, 0,
                 "image is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                     " but the image list (and its intrinsics) says " + std::to_string(info.width) +
                     "x" + std::to_string(info.height) +
                     (gray.cols == info.height && gray.rows == info.width
                          ? " (width and height swapped: the decoder turned it by 90° as its EXIF "
                            "orientation tag says; save the image without the tag, or give "
                            "intrinsics for the image as decoded)"
                          : ""));
    }
    (*features)[i] = ExtractSift(gray, options);
    upsampled[i] = EffectiveFirstOctave(gray.cols, gray.rows, options) < 0;
    // On a terminal the bar shows the count; the per-image lines stay in the debug log.
    const std::string line =
        fmt::format("features: [{}/{}] {}: {} keypoints in {:.2f} s", ++done, num_images, info.name,
                    (*features)[i].keypoints.rows(), SecondsSince(image_start));
    if (bar.drawing()) {
      spdlog::debug(line);
    } else {
      spdlog::info(line);
    }
    bar.Update(done.load(), info.name);
  });

  FeatureExtractionSummary summary;
  summary.num_images = num_images;
  summary.upsampled.assign(upsampled.begin(), upsampled.end());
  summary.num_upsampled =
      static_cast<int>(std::count(summary.upsampled.begin(), summary.upsampled.end(), true));
  summary.min_keypoints = num_images > 0 ? std::numeric_limits<int>::max() : 0;
  for (const ImageFeatures& f : *features) {
    const int count = static_cast<int>(f.keypoints.rows());
    summary.num_keypoints += count;
    summary.min_keypoints = std::min(summary.min_keypoints, count);
    summary.max_keypoints = std::max(summary.max_keypoints, count);
  }
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace raytime
