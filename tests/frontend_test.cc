// The front end (frontend/, SPEC §5, issue 3): matching kernels against a brute-force reference,
// SIFT keypoint positions on a synthetic blob, the verification pipeline on a synthetic two-view
// scene with known geometry (distorted and undistorted). The sample scene's checks are in
// frontend_sample_test.cc.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "core/camera.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/written_files.h"
#include "formats/strecha.h"
#include "frontend/descriptor_matching.h"
#include "frontend/feature_extraction.h"
#include "frontend/image_reading.h"
#include "frontend/matching.h"
#include "frontend/two_view_geometry.h"
#include "frontend/video_frames.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// Quantized descriptors with the full byte range (entries above 127 exercise the byte kernel's
// signed bytes, stored as b - 128), an all-zero row, and a repeated row for ties.
ByteDescriptors RandomByteDescriptors(int rows, int dim, std::mt19937* rng) {
  std::uniform_int_distribution<int> byte(0, 255);
  ByteDescriptors out(rows, dim);
  for (int i = 0; i < rows; ++i) {
    for (int k = 0; k < dim; ++k) out(i, k) = static_cast<uint8_t>(byte(*rng));
  }
  if (rows > 4) out.row(4).setZero();
  if (rows > 10) out.row(10) = out.row(3);
  return out;
}

// The similarities by brute force on exact integer dot products, as the kernels promise
// (descriptor_matching.h: dot · 1/|a| · 1/|b| in float, a from the first image, for both
// directions).
Eigen::MatrixXf ReferenceSimilarities(const ByteDescriptors& a, const ByteDescriptors& b) {
  // Plain loops over the bytes with each row's norm computed once: the reference runs unoptimized
  // under the sanitizers, where Eigen expressions per pair took a minute.
  const auto squared_norms = [](const ByteDescriptors& d) {
    std::vector<int64_t> out(d.rows(), 0);
    for (int i = 0; i < d.rows(); ++i) {
      for (int k = 0; k < d.cols(); ++k) out[i] += int64_t{d(i, k)} * d(i, k);
    }
    return out;
  };
  const auto inverse_norm = [](int64_t sum) {
    return sum > 0 ? static_cast<float>(1.0 / std::sqrt(static_cast<double>(sum))) : 0.0f;
  };
  const std::vector<int64_t> a2 = squared_norms(a), b2 = squared_norms(b);
  const int dim = static_cast<int>(a.cols());
  Eigen::MatrixXf out(a.rows(), b.rows());
  double worst = 0.0;  // the float similarity against the cosine in double
  for (int i = 0; i < a.rows(); ++i) {
    const uint8_t* ai = &a(i, 0);
    for (int j = 0; j < b.rows(); ++j) {
      const uint8_t* bj = &b(j, 0);
      int64_t dot = 0;
      for (int k = 0; k < dim; ++k) dot += int64_t{ai[k]} * bj[k];
      out(i, j) = static_cast<float>(dot) * inverse_norm(a2[i]) * inverse_norm(b2[j]);
      const double norms =
          std::sqrt(static_cast<double>(a2[i])) * std::sqrt(static_cast<double>(b2[j]));
      const double cosine = norms > 0 ? static_cast<double>(dot) / norms : 0.0;
      worst = std::max(worst, std::abs(out(i, j) - cosine));
    }
  }
  // The similarity is the cosine of the two descriptors to float precision.
  EXPECT_LT(worst, 1e-6);
  return out;
}

// Top-2 of each row; ties go to the smallest index.
NeighborList ReferenceNeighbors(const Eigen::MatrixXf& similarities) {
  const float none = -std::numeric_limits<float>::infinity();
  const int n = static_cast<int>(similarities.rows());
  NeighborList out{std::vector<int>(n, -1), std::vector<float>(n, none),
                   std::vector<float>(n, none)};
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < similarities.cols(); ++j) {
      const float similarity = similarities(i, j);
      if (similarity > out.best[i]) {
        out.second[i] = out.best[i];
        out.best[i] = similarity;
        out.index[i] = j;
      } else if (similarity > out.second[i]) {
        out.second[i] = similarity;
      }
    }
  }
  return out;
}

void ExpectSameNeighbors(const NeighborList& got, const NeighborList& expected) {
  ASSERT_EQ(got.index.size(), expected.index.size());
  for (size_t i = 0; i < expected.index.size(); ++i) {
    EXPECT_EQ(got.index[i], expected.index[i]) << "row " << i;
    EXPECT_EQ(got.best[i], expected.best[i]) << "row " << i;
    EXPECT_EQ(got.second[i], expected.second[i]) << "row " << i;
  }
}

// Every kernel finds exactly the brute-force neighbours, similarities equal to the bit: the
// products are exact integers whichever kernel ran, so no CPU finds other matches.
TEST(MatchingKernel, EveryKernelFindsTheBruteForceNeighboursToTheBit) {
  std::mt19937 rng(7);
  // Sizes straddle the kernels' blocking: 6-row tiles, 16-column panels, 1024-column blocks,
  // 256-row GEMM blocks; single rows and columns have no second neighbour; an odd length pads
  // the byte kernel's groups of four dimensions.
  const std::vector<std::tuple<int, int, int>> sizes = {
      {1, 1, 128},     {1, 5, 128},      {7, 1, 128},     {13, 17, 128},
      {300, 257, 128}, {257, 1100, 128}, {1030, 40, 128}, {13, 17, 7}};
  std::vector<MatchKernel> kernels = {MatchKernel::kGemm};
  if (CpuHasAvx2Fma()) kernels.push_back(MatchKernel::kAvx2);
  if (CpuHasVnni()) kernels.push_back(MatchKernel::kVnni);
  for (const auto& [n, m, dim] : sizes) {
    const ByteDescriptors a = RandomByteDescriptors(n, dim, &rng);
    const ByteDescriptors b = RandomByteDescriptors(m, dim, &rng);
    const Eigen::MatrixXf similarities = ReferenceSimilarities(a, b);
    const NeighborList ab_reference = ReferenceNeighbors(similarities);
    const NeighborList ba_reference = ReferenceNeighbors(similarities.transpose());
    for (const MatchKernel kernel : kernels) {
      SCOPED_TRACE(std::string(MatchKernelName(kernel)) + " " + std::to_string(n) + "x" +
                   std::to_string(m) + "x" + std::to_string(dim));
      NeighborList ab, ba;
      FindNeighbors(a, b, kernel, &ab, &ba);
      ExpectSameNeighbors(ab, ab_reference);
      ExpectSameNeighbors(ba, ba_reference);
    }
  }
}

// Guided matching's candidates are the pairs within the Sampson bound, by the same float
// expressions on every kernel (fused multiply-adds included): its matches equal an all-pairs scan's
// written out here, to the match. Two views of random points, descriptors of a point alike in both
// views, plus clutter keypoints in each.
TEST(MatchingKernel, GuidedMatchingFindsTheAllPairsMatches) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_int_distribution<int> byte(0, 255), jitter(-6, 6);
  const double f = 1200.0, cx = 768.0, cy = 512.0, max_error = 4.0;
  const Eigen::Matrix3d K = (Eigen::Matrix3d() << f, 0, cx, 0, f, cy, 0, 0, 1).finished();
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1.0, 0.05).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(-1.0, 0.1, 0.2);
  const Eigen::Matrix3d tx =
      (Eigen::Matrix3d() << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0).finished();
  const Eigen::Matrix3d F = K.inverse().transpose() * tx * R * K.inverse();
  const int num_points = 600, clutter = 300;
  ByteDescriptors a(num_points + clutter, 128), b(num_points + clutter, 128);
  Eigen::Matrix<double, Eigen::Dynamic, 2> x1(num_points + clutter, 2), x2(num_points + clutter, 2);
  for (int p = 0; p < num_points; ++p) {
    const Eigen::Vector3d X(4.0 * unit(rng), 3.0 * unit(rng), 8.0 + 4.0 * unit(rng));
    const Eigen::Vector3d p1 = K * X, p2 = K * (R * X + t);
    x1.row(p) << p1.x() / p1.z(), p1.y() / p1.z();
    // Up to ~5 px off the epipolar line: some candidates sit near the threshold.
    x2.row(p) << p2.x() / p2.z() + 3.0 * unit(rng), p2.y() / p2.z() + 3.0 * unit(rng);
    for (int k = 0; k < 128; ++k) {
      a(p, k) = static_cast<uint8_t>(byte(rng));
      b(p, k) = static_cast<uint8_t>(std::clamp(a(p, k) + jitter(rng), 0, 255));
    }
  }
  for (int p = num_points; p < num_points + clutter; ++p) {
    x1.row(p) << 1536.0 * (0.5 + 0.5 * unit(rng)), 1024.0 * (0.5 + 0.5 * unit(rng));
    x2.row(p) << 1536.0 * (0.5 + 0.5 * unit(rng)), 1024.0 * (0.5 + 0.5 * unit(rng));
    for (int k = 0; k < 128; ++k) {
      a(p, k) = static_cast<uint8_t>(byte(rng));
      b(p, k) = static_cast<uint8_t>(byte(rng));
    }
  }
  // The all-pairs scan, written out: GuidedMatches' inputs and test (descriptor_matching.cc).
  const Eigen::Matrix3d Fn = F / F.norm();
  const float e2 = static_cast<float>(max_error * max_error);
  const Eigen::MatrixXf similarities = ReferenceSimilarities(a, b);
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(b.rows());
  Eigen::MatrixXf candidates =
      Eigen::MatrixXf::Constant(n, m, -std::numeric_limits<float>::infinity());
  // Each second-view point's gradient term, once (the scan runs unoptimized under the sanitizers).
  std::vector<float> g2(m), u2(m), v2(m);
  for (int j = 0; j < m; ++j) {
    const Eigen::Vector3d g = Fn.transpose() * Eigen::Vector3d(x2(j, 0), x2(j, 1), 1.0);
    g2[j] = static_cast<float>(g.x() * g.x() + g.y() * g.y());
    u2[j] = static_cast<float>(x2(j, 0));
    v2[j] = static_cast<float>(x2(j, 1));
  }
  int num_candidates = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d l = Fn * Eigen::Vector3d(x1(i, 0), x1(i, 1), 1.0);
    const float l0 = static_cast<float>(l.x()), l1 = static_cast<float>(l.y()),
                l2 = static_cast<float>(l.z());
    const float bound = e2 * (l0 * l0 + l1 * l1);
    for (int j = 0; j < m; ++j) {
      const float r = std::fma(l0, u2[j], std::fma(l1, v2[j], l2));
      if (r * r < std::fma(e2, g2[j], bound)) {
        candidates(i, j) = similarities(i, j);
        ++num_candidates;
      }
    }
  }
  const MatchList expected = RatioTestMatches(
      ReferenceNeighbors(candidates), ReferenceNeighbors(candidates.transpose()), 0.8, 0.7, true);
  EXPECT_GT(num_candidates, n);  // the band holds more than the true matches
  EXPECT_GT(expected.rows(), num_points / 2);
  std::vector<MatchKernel> kernels = {MatchKernel::kGemm};
  if (CpuHasAvx2Fma()) kernels.push_back(MatchKernel::kAvx2);
  for (const MatchKernel kernel : kernels) {
    const MatchList got = GuidedMatches(a, b, x1, x2, F, max_error, 0.8, 0.7, true, kernel);
    ASSERT_EQ(got.rows(), expected.rows()) << MatchKernelName(kernel);
    EXPECT_TRUE(got == expected) << MatchKernelName(kernel);
  }
}

TEST(MatchingKernel, RatioTestAndMutualCheck) {
  // Row 0 -> 0 is clear and mutual; row 1 -> 0 loses the mutual check; row 2 fails the ratio.
  NeighborList ab{{0, 0, 1}, {0.99f, 0.95f, 0.90f}, {0.2f, 0.1f, 0.89f}};
  NeighborList ba{{0, 2}, {0.99f, 0.90f}, {0.95f, 0.3f}};
  const MatchList mutual = RatioTestMatches(ab, ba, 0.8, 0.7, true);
  ASSERT_EQ(mutual.rows(), 1);
  EXPECT_EQ(mutual(0, 0), 0u);
  EXPECT_EQ(mutual(0, 1), 0u);
  // Without the mutual check row 1 is kept; row 0 no longer needs column 0 to pass.
  EXPECT_EQ(RatioTestMatches(ab, ba, 0.8, 0.7, false).rows(), 2);
  // A single candidate passes the ratio test (the missing second counts as orthogonal) but not
  // the absolute bound: dot 0.6 is distance 0.89 > 0.7.
  const float none = -std::numeric_limits<float>::infinity();
  NeighborList single{{0, 0}, {0.9f, 0.6f}, {none, none}};
  NeighborList back{{0}, {0.9f}, {none}};
  const MatchList bounded = RatioTestMatches(single, back, 0.8, 0.7, false);
  ASSERT_EQ(bounded.rows(), 1);
  EXPECT_EQ(bounded(0, 0), 0u);
}

TEST(Features, RootSiftQuantization) {
  cv::Mat d(1, 4, CV_32F);
  d.at<float>(0) = 9;
  d.at<float>(1) = 16;
  d.at<float>(2) = 0;
  d.at<float>(3) = 75;
  // L1 norm 100: sqrt -> 0.3, 0.4, 0, sqrt(0.75) = 0.866; x 512, saturated at 255.
  const ByteDescriptors q = QuantizeSiftDescriptors(d, true);
  EXPECT_EQ(q(0, 0), 154);
  EXPECT_EQ(q(0, 1), 205);
  EXPECT_EQ(q(0, 2), 0);
  EXPECT_EQ(q(0, 3), 255);
}

// A dark blob on a bright background at a sub-pixel position: the detected keypoint must sit on
// it in the OpenCV pixel convention (corrects OpenCV 4.6's 0.25 px upsampling shift).
TEST(Features, KeypointPositionsUseOpenCvPixelConvention) {
  const double cx = 100.0, cy = 80.0, sigma = 4.0;
  cv::Mat image(160, 200, CV_8U);
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const double r2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
      image.at<uint8_t>(y, x) =
          cv::saturate_cast<uint8_t>(40 + 180 * std::exp(-r2 / (2 * sigma * sigma)));
    }
  }
  for (const int first_octave : {-1, 0}) {
    FeatureExtractionOptions options;
    options.first_octave = first_octave;
    const ImageFeatures features = ExtractSift(image, options);
    ASSERT_GT(features.keypoints.rows(), 0) << "first_octave " << first_octave;
    // The strongest keypoint is the blob.
    EXPECT_NEAR(features.keypoints(0, 0), cx, 0.1) << "first_octave " << first_octave;
    EXPECT_NEAR(features.keypoints(0, 1), cy, 0.1) << "first_octave " << first_octave;
    // Scale: the sigma of the blob (the scale-normalized Laplacian peaks there).
    EXPECT_NEAR(features.keypoints(0, 2), sigma, 1.0);
    EXPECT_EQ(features.descriptors.cols(), 128);
  }
}

// A large textured image: smoothed random noise, so every DoG level holds many extrema.
cv::Mat TexturedImage(int width, int height, unsigned seed) {
  cv::Mat noise(height, width, CV_32F);
  std::mt19937 rng(seed);
  std::normal_distribution<float> gauss(0.0f, 1.0f);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) noise.at<float>(y, x) = gauss(rng);
  }
  cv::Mat fine, coarse, image;
  cv::GaussianBlur(noise, fine, cv::Size(), 2.0);
  cv::GaussianBlur(noise, coarse, cv::Size(), 8.0);
  cv::normalize(fine + 4.0f * coarse, image, 0, 255, cv::NORM_MINMAX, CV_8U);
  return image;
}

// DoG level of an OpenCV SIFT keypoint, ordered coarsest first: (octave, layer).
std::pair<int, int> Level(const cv::KeyPoint& kp) {
  return {static_cast<int8_t>(kp.octave & 255), (kp.octave >> 8) & 255};
}

// The budget holds on a large image and keeps the coarsest DoG levels whole, then the strongest of
// the level that crosses it (COLMAP's per-level rule, cut within the last level by response).
TEST(Features, BudgetKeepsWholeCoarseLevelsThenTheStrongest) {
  const cv::Mat image = TexturedImage(1000, 750, 5);
  const cv::Ptr<cv::SIFT> sift = cv::SIFT::create(0, 3, 0.02, 10.0, 1.6);
  std::vector<cv::KeyPoint> detected;
  sift->detect(image, detected);
  const int budget = 1500;
  ASSERT_GT(static_cast<int>(detected.size()), 2 * budget) << "the image must exceed the budget";
  const std::vector<cv::KeyPoint> kept = SelectKeypoints(detected, budget);
  EXPECT_LE(static_cast<int>(kept.size()), budget);
  EXPECT_GE(static_cast<int>(kept.size()), budget - 4);  // a location's orientations stay together

  const auto key = [](const cv::KeyPoint& kp) {
    return std::make_tuple(kp.pt.x, kp.pt.y, kp.size, kp.octave, kp.angle);
  };
  std::set<std::tuple<float, float, float, int, float>> kept_keys;
  for (const auto& kp : kept) kept_keys.insert(key(kp));
  // The finest level with a kept keypoint is the cut level (levels sort coarsest first as the
  // larger (octave, layer)).
  std::pair<int, int> cut = Level(kept.front());
  for (const auto& kp : kept) cut = std::min(cut, Level(kp));
  float weakest_kept_at_cut = std::numeric_limits<float>::max();
  float strongest_dropped_at_cut = 0;
  int coarser = 0, finer_kept = 0, cut_dropped = 0;
  for (const auto& kp : detected) {
    const bool is_kept = kept_keys.count(key(kp)) > 0;
    if (Level(kp) > cut) {
      ++coarser;
      EXPECT_TRUE(is_kept) << "a coarser level than the cut lost a keypoint";
    } else if (Level(kp) < cut) {
      finer_kept += is_kept;
    } else if (is_kept) {
      weakest_kept_at_cut = std::min(weakest_kept_at_cut, kp.response);
    } else {
      ++cut_dropped;
      strongest_dropped_at_cut = std::max(strongest_dropped_at_cut, kp.response);
    }
  }
  EXPECT_EQ(finer_kept, 0);
  EXPECT_GT(coarser, 0);
  EXPECT_GT(cut_dropped, 0) << "the budget should cut within a level";
  EXPECT_GE(weakest_kept_at_cut, strongest_dropped_at_cut);
  // Output order: strongest first.
  for (size_t k = 1; k < kept.size(); ++k) EXPECT_GE(kept[k - 1].response, kept[k].response);

  // The same through ExtractSift, which describes only the kept keypoints.
  FeatureExtractionOptions options;
  options.max_features = budget;
  options.first_octave = 0;
  const ImageFeatures features = ExtractSift(image, options);
  EXPECT_LE(features.keypoints.rows(), budget);
  EXPECT_GE(features.keypoints.rows(), budget - 4);
  EXPECT_EQ(features.descriptors.rows(), features.keypoints.rows());
  // A budget above the detection keeps everything.
  EXPECT_EQ(SelectKeypoints(detected, static_cast<int>(detected.size())).size(), detected.size());
}

TEST(Features, LargeImagesAreNotUpsampled) {
  FeatureExtractionOptions options;  // first_octave -1, upsample_max_size 1600
  EXPECT_EQ(EffectiveFirstOctave(768, 512, options), -1);    // the sample scene
  EXPECT_EQ(EffectiveFirstOctave(1536, 1024, options), -1);  // the shared Strecha scenes
  EXPECT_EQ(EffectiveFirstOctave(1920, 1440, options), 0);   // 3D Scanner App
  EXPECT_EQ(EffectiveFirstOctave(1440, 1920, options), 0);   // Record3D, portrait
  options.upsample_max_size = 0;
  EXPECT_EQ(EffectiveFirstOctave(1920, 1440, options), -1);
  options.first_octave = 1;
  EXPECT_EQ(EffectiveFirstOctave(768, 512, options), 1);
}

// The InputError of extracting the features of the one image `name` (width x height) in `dir`, or
// "" when there is none.
std::string FeatureExtractionError(const TempDir& dir, const std::string& name, int width,
                                   int height) {
  ImageSet images;
  images.image_root = dir.path().string();
  images.cameras.resize(1);
  images.images.push_back({name, width, height, 0});
  std::vector<ImageFeatures> features;
  try {
    ExtractFeatures(images, FeatureExtractionOptions(), &features);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(Features, UnreadableImageIsAnInputErrorNamingTheFile) {
  TempDir dir("frontend");
  std::ofstream(dir / "broken.jpg") << "not a jpeg";
  const std::string error = FeatureExtractionError(dir, "broken.jpg", 10, 10);
  EXPECT_NE(error.find("broken.jpg"), std::string::npos) << error;
}

// ---- Image files: a damaged file is an error naming it, a valid one is read as OpenCV reads it.
// --

using Bytes = std::vector<uint8_t>;

Bytes ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::string WriteBytes(const std::string& path, const Bytes& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  return path;
}

Bytes Encode(const std::string& extension, const cv::Mat& image,
             const std::vector<int>& parameters = {}) {
  Bytes bytes;
  EXPECT_TRUE(cv::imencode(extension, image, bytes, parameters));
  return bytes;
}

Bytes Head(const Bytes& bytes, size_t count) { return Bytes(bytes.begin(), bytes.begin() + count); }

const std::string kSampleImage =
    std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11/images/0000.jpg";

// ReadImage's error message on `path`, or "" when it reads the file.
std::string ReadImageError(const std::string& path) {
  try {
    ReadImage(path, cv::IMREAD_GRAYSCALE);
    return "";
  } catch (const InputError& e) {
    return e.what();
  }
}

bool SamePixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

TEST(ImageReading, TruncatedSampleJpegIsAnErrorNamingTheFile) {
  TempDir dir("frontend");
  const Bytes full = ReadBytes(kSampleImage);
  const std::string path = WriteBytes(dir / "half.jpg", Head(full, full.size() / 2));
  // What issue 13 saw: OpenCV decodes it (the missing half grey) with a warning naming no file.
  EXPECT_FALSE(cv::imread(path, cv::IMREAD_GRAYSCALE).empty());
  const std::string error = ReadImageError(path);
  EXPECT_NE(error.find(path), std::string::npos) << error;
  EXPECT_NE(error.find("truncated JPEG: no end-of-image marker"), std::string::npos) << error;
  // Cut anywhere: in a header segment, one byte short of the end-of-image marker.
  for (const size_t size : {size_t(3), size_t(100), full.size() - 1}) {
    EXPECT_NE(ReadImageError(WriteBytes(dir / "cut.jpg", Head(full, size))).find("truncated JPEG"),
              std::string::npos)
        << size << " bytes";
  }
  // The features stage reports it rather than extracting features from half an image.
  const std::string features_error = FeatureExtractionError(dir, "half.jpg", 768, 512);
  EXPECT_NE(features_error.find("half.jpg: truncated JPEG"), std::string::npos) << features_error;
}

TEST(ImageReading, CorruptJpegSegmentsAreErrors) {
  TempDir dir("frontend");
  Bytes bytes = ReadBytes(kSampleImage);
  bytes[2] = 0x00;  // the first marker after SOI
  EXPECT_NE(
      ReadImageError(WriteBytes(dir / "a.jpg", bytes)).find("corrupt JPEG: expected a marker"),
      std::string::npos);
  bytes = ReadBytes(kSampleImage);
  bytes[4] = bytes[5] = 0;  // the first segment's length
  EXPECT_NE(ReadImageError(WriteBytes(dir / "b.jpg", bytes)).find("corrupt JPEG"),
            std::string::npos);
}

TEST(ImageReading, ValidFilesReadAsOpenCvReadsThem) {
  TempDir dir("frontend");
  const cv::Mat reference = cv::imread(kSampleImage, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(reference.empty());
  EXPECT_TRUE(SamePixels(ReadImage(kSampleImage, cv::IMREAD_GRAYSCALE), reference));
  EXPECT_TRUE(SamePixels(ReadImage(kSampleImage, cv::IMREAD_COLOR),
                         cv::imread(kSampleImage, cv::IMREAD_COLOR)));

  // Data after the end-of-image marker (some cameras append metadata or a second image).
  Bytes trailing = ReadBytes(kSampleImage);
  for (const uint8_t b : {0xFF, 0xD8, 0xFF, 0xE1, 0x00, 0x10, 0x42}) trailing.push_back(b);
  trailing.insert(trailing.end(), 1000, 0x5A);
  const std::string trailing_path = WriteBytes(dir / "trailing.jpg", trailing);
  EXPECT_EQ(ReadImageError(trailing_path), "");
  EXPECT_TRUE(SamePixels(ReadImage(trailing_path, cv::IMREAD_GRAYSCALE), reference));

  // A progressive JPEG: several scans, tables between them.
  const Bytes progressive = Encode(".jpg", reference, {cv::IMWRITE_JPEG_PROGRESSIVE, 1});
  const std::string progressive_path = WriteBytes(dir / "progressive.jpg", progressive);
  EXPECT_EQ(ReadImageError(progressive_path), "");
  EXPECT_TRUE(SamePixels(ReadImage(progressive_path, cv::IMREAD_GRAYSCALE),
                         cv::imread(progressive_path, cv::IMREAD_GRAYSCALE)));
  EXPECT_NE(ReadImageError(WriteBytes(dir / "p.jpg", Head(progressive, progressive.size() * 3 / 4)))
                .find("truncated JPEG"),
            std::string::npos);

  // An EXIF thumbnail: a whole JPEG, with its own end-of-image marker, inside an APP1 segment
  // (Exif header, then a TIFF header with an empty IFD, then the thumbnail).
  cv::Mat small;
  cv::resize(reference, small, cv::Size(64, 43));
  const Bytes thumbnail = Encode(".jpg", small);
  Bytes app1 = {'E', 'x', 'i', 'f', 0, 0, 'I', 'I', 42, 0, 8, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  app1.insert(app1.end(), thumbnail.begin(), thumbnail.end());
  const size_t length = app1.size() + 2;
  ASSERT_LT(length, 65536u);
  const Bytes main = ReadBytes(kSampleImage);
  Bytes exif = {0xFF, 0xD8, 0xFF, 0xE1, uint8_t(length >> 8), uint8_t(length & 255)};
  exif.insert(exif.end(), app1.begin(), app1.end());
  exif.insert(exif.end(), main.begin() + 2, main.end());
  const std::string exif_path = WriteBytes(dir / "exif.jpg", exif);
  EXPECT_EQ(ReadImageError(exif_path), "");
  EXPECT_TRUE(SamePixels(ReadImage(exif_path, cv::IMREAD_GRAYSCALE), reference));
  // Cut right after the thumbnail: its end-of-image marker is not the file's.
  EXPECT_NE(ReadImageError(WriteBytes(dir / "e.jpg", Head(exif, 6 + app1.size() + 100)))
                .find("truncated JPEG"),
            std::string::npos);
}

TEST(ImageReading, TruncatedPngIsAnErrorNamingTheFile) {
  TempDir dir("frontend");
  const cv::Mat reference = cv::imread(kSampleImage, cv::IMREAD_GRAYSCALE);
  const Bytes png = Encode(".png", reference);
  const std::string valid = WriteBytes(dir / "valid.png", png);
  EXPECT_TRUE(SamePixels(ReadImage(valid, cv::IMREAD_GRAYSCALE), reference));
  Bytes trailing = png;
  trailing.insert(trailing.end(), 100, 0x00);
  EXPECT_EQ(ReadImageError(WriteBytes(dir / "trailing.png", trailing)), "");
  for (const size_t size : {png.size() / 2, png.size() - 1, size_t(12)}) {
    const std::string path = WriteBytes(dir / "cut.png", Head(png, size));
    const std::string error = ReadImageError(path);
    EXPECT_NE(error.find(path + ": truncated PNG: no IEND chunk"), std::string::npos)
        << size << " bytes: " << error;
  }
}

// ---- Synthetic two-view scene with exact correspondences. ----

struct SyntheticPair {
  ImageSet images;
  std::vector<ImageFeatures> features;
  Rigid3 cam2_from_cam1;
  int num_points = 0;
};

// Points in front of two cameras; each point gets one random descriptor shared by its two
// observations, and each image also gets unmatched clutter keypoints.
SyntheticPair MakeSyntheticPair(const CameraIntrinsics& camera, int num_points, int clutter) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  SyntheticPair pair;
  pair.images.cameras = {camera};
  pair.images.images = {{"a.png", camera.width, camera.height, 0},
                        {"b.png", camera.width, camera.height, 0}};
  pair.cam2_from_cam1 = Rigid3(Eigen::Quaterniond(ExpSO3(Eigen::Vector3d(0.02, -0.15, 0.03))),
                               Eigen::Vector3d(-1.0, 0.1, 0.2));
  std::vector<Eigen::Vector2d> kp[2];
  std::vector<int> descriptor_id[2];
  int id = 0;
  while (static_cast<int>(kp[0].size()) < num_points) {
    const double z = 8 + 4 * u(rng);
    const double y = 3 * u(rng);
    const Eigen::Vector3d p1(4 * u(rng), y, z);
    const Eigen::Vector3d p2 = pair.cam2_from_cam1 * p1;
    double pix[2][2];
    ProjectPinhole(camera.params.data(), p1.data(), pix[0]);
    ProjectPinhole(camera.params.data(), p2.data(), pix[1]);
    bool inside = p2.z() > 0;
    for (int v = 0; v < 2; ++v) {
      double distorted[2];
      DistortPixel(camera.params.data(), pix[v], distorted);
      pix[v][0] = distorted[0];
      pix[v][1] = distorted[1];
      inside = inside && pix[v][0] > 0 && pix[v][1] > 0 && pix[v][0] < camera.width - 1 &&
               pix[v][1] < camera.height - 1;
    }
    if (!inside) continue;
    for (int v = 0; v < 2; ++v) {
      kp[v].emplace_back(pix[v][0], pix[v][1]);
      descriptor_id[v].push_back(id);
    }
    ++id;
  }
  pair.num_points = num_points;
  for (int v = 0; v < 2; ++v) {
    for (int c = 0; c < clutter; ++c) {
      const double y = camera.height * 0.5 * (1 + u(rng));
      kp[v].emplace_back(camera.width * 0.5 * (1 + u(rng)), y);
      descriptor_id[v].push_back(id++);
    }
  }
  // Sparse like SIFT: unrelated descriptors are far apart (cosine ~0.2).
  std::uniform_int_distribution<int> byte(1, 255);
  std::bernoulli_distribution nonzero(0.3);
  std::vector<std::array<uint8_t, 128>> descriptors(id);
  for (auto& d : descriptors) {
    for (auto& value : d) value = nonzero(rng) ? static_cast<uint8_t>(byte(rng)) : 0;
  }
  pair.features.resize(2);
  for (int v = 0; v < 2; ++v) {
    ImageFeatures& f = pair.features[v];
    f.keypoints.resize(kp[v].size(), 4);
    f.descriptors.resize(kp[v].size(), 128);
    for (size_t k = 0; k < kp[v].size(); ++k) {
      f.keypoints.row(k) << kp[v][k].x(), kp[v][k].y(), 2.0f, 0.0f;
      for (int c = 0; c < 128; ++c) f.descriptors(k, c) = descriptors[descriptor_id[v][k]][c];
    }
  }
  return pair;
}

CameraIntrinsics SyntheticCamera(double k1) {
  CameraIntrinsics camera;
  camera.width = 1000;
  camera.height = 750;
  camera.params = {800, 810, 499.5, 374.5, k1, 0.5 * k1 * k1, 0.0005, -0.0003};
  return camera;
}

TEST(Verification, RecoversTheRelativePoseWithDistortion) {
  const SyntheticPair pair = MakeSyntheticPair(SyntheticCamera(-0.25), 400, 200);
  MatchingOptions options;
  std::vector<PairMatches> pairs;
  const MatchingSummary summary = MatchImages(pair.images, pair.features, options, &pairs);
  ASSERT_EQ(pairs.size(), 1u);
  const TwoViewGeometry& g = pairs[0].geometry;
  EXPECT_EQ(g.config, TwoViewConfig::kCalibrated);
  // Every true correspondence verifies (the points are exact once undistorted) ...
  EXPECT_GE(g.inlier_matches.rows(), pair.num_points * 0.98);
  // ... and only those: the clutter has its own descriptors and indices past num_points.
  for (Eigen::Index k = 0; k < g.inlier_matches.rows(); ++k) {
    EXPECT_EQ(g.inlier_matches(k, 0), g.inlier_matches(k, 1));
  }
  EXPECT_LT(
      DegreesFromRadians(RotationDistance(g.cam2_from_cam1.rotation, pair.cam2_from_cam1.rotation)),
      0.01);
  EXPECT_LT(DegreesFromRadians(std::acos(std::clamp(
                g.cam2_from_cam1.translation.dot(pair.cam2_from_cam1.translation.normalized()),
                -1.0, 1.0))),
            0.1);
  EXPECT_EQ(summary.num_verified_pairs, 1);
}

TEST(Verification, DistortionIgnoredLosesInliers) {
  // The same scene read as if undistorted: the essential matrix no longer explains the points,
  // which shows that the previous test depends on the undistortion.
  SyntheticPair pair = MakeSyntheticPair(SyntheticCamera(-0.25), 400, 0);
  pair.images.cameras[0].params[kK1] = pair.images.cameras[0].params[kK2] = 0;
  pair.images.cameras[0].params[kP1] = pair.images.cameras[0].params[kP2] = 0;
  MatchingOptions options;
  options.ransac_error_px = 1.0;
  options.max_error_px = 1.0;
  options.guided_matching = false;
  std::vector<PairMatches> pairs;
  MatchImages(pair.images, pair.features, options, &pairs);
  const Eigen::Index inliers = pairs.empty() ? 0 : pairs[0].geometry.inlier_matches.rows();
  EXPECT_LT(inliers, pair.num_points * 0.9);
}

TEST(Verification, FundamentalMatrixWithoutIntrinsics) {
  const SyntheticPair pair = MakeSyntheticPair(SyntheticCamera(0.0), 300, 100);
  MatchingOptions options;
  options.geometry = "fundamental";
  std::vector<PairMatches> pairs;
  MatchImages(pair.images, pair.features, options, &pairs);
  ASSERT_EQ(pairs.size(), 1u);
  const TwoViewGeometry& g = pairs[0].geometry;
  EXPECT_EQ(g.config, TwoViewConfig::kUncalibrated);
  EXPECT_GE(g.inlier_matches.rows(), pair.num_points * 0.98);
  PointList x1(g.inlier_matches.rows(), 2), x2(g.inlier_matches.rows(), 2);
  for (Eigen::Index k = 0; k < x1.rows(); ++k) {
    x1.row(k) = pair.features[0].keypoints.row(g.inlier_matches(k, 0)).head<2>().cast<double>();
    x2.row(k) = pair.features[1].keypoints.row(g.inlier_matches(k, 1)).head<2>().cast<double>();
  }
  EXPECT_LT(SampsonDistances(g.F, x1, x2).maxCoeff(), 0.1);
}

TEST(Matching, SequentialPairsAreAWindowPlusAKeyframeGrid) {
  MatchingOptions options;
  options.pairs = "sequential";
  options.window = 2;
  options.loop_stride = 4;
  const auto pairs = SelectPairs(10, options);
  const std::set<std::pair<int, int>> got(pairs.begin(), pairs.end());
  std::set<std::pair<int, int>> expected;
  for (int i = 0; i < 10; ++i) {
    for (int j = i + 1; j <= std::min(9, i + 2); ++j) expected.emplace(i, j);
  }
  expected.insert({{0, 4}, {0, 8}, {4, 8}});
  EXPECT_EQ(got, expected);
  EXPECT_TRUE(std::is_sorted(pairs.begin(), pairs.end()));
  options.pairs = "exhaustive";
  EXPECT_EQ(SelectPairs(10, options).size(), 45u);
}

TEST(Matching, BadOptionsAreInputErrors) {
  MatchingOptions options;
  options.pairs = "sequentail";
  EXPECT_THROW(ValidateOptions(options, "test"), InputError);
  options = MatchingOptions();
  options.min_num_inliers = 3;
  EXPECT_THROW(ValidateOptions(options, "test"), InputError);
  options = MatchingOptions();
  options.estimator = "lmeds";
  EXPECT_THROW(ValidateOptions(options, "test"), InputError);
}

// ---- Video input. ----

TEST(Video, FramesAreSampledByStrideOrCount) {
  TempDir dir("frontend");
  const std::string video = dir / "clip.avi";
  {
    cv::VideoWriter writer(video, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10,
                           cv::Size(160, 120));
    ASSERT_TRUE(writer.isOpened());
    for (int f = 0; f < 10; ++f) {
      cv::Mat frame(120, 160, CV_8UC3, cv::Scalar(20 * f, 100, 200 - 15 * f));
      writer.write(frame);
    }
  }
  VideoFramesOptions options;
  options.video = video;
  options.stride = 3;
  options.focal_px = 150;
  VideoFramesSummary summary;
  ImageSet images = ExtractVideoFrames(options, dir / "frames", &summary);
  ASSERT_EQ(images.images.size(), 4u);  // frames 0, 3, 6, 9
  EXPECT_EQ(images.images[1].name, "frame_000003.jpg");
  EXPECT_EQ(summary.num_frames_read, 10);
  EXPECT_EQ(images.cameras.at(0).fx(), 150);
  EXPECT_EQ(images.cameras.at(0).cx(), 79.5);
  EXPECT_TRUE(fs::exists(fs::path(images.image_root) / images.images[3].name));
  options.num_frames = 2;
  images = ExtractVideoFrames(options, dir / "frames", &summary);
  ASSERT_EQ(images.images.size(), 2u);
  EXPECT_EQ(images.images[0].name, "frame_000000.jpg");
  EXPECT_EQ(images.images[1].name, "frame_000009.jpg");
  // The two frames and the record of what raytime wrote there (core/written_files.h).
  EXPECT_EQ(
      std::distance(fs::directory_iterator(fs::path(dir / "frames")), fs::directory_iterator()), 3);
  EXPECT_TRUE(fs::exists(fs::path(dir / "frames") / kWrittenFilesRecord));

  options.video = dir / "missing.mp4";
  try {
    ExtractVideoFrames(options, dir / "frames2", &summary);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.mp4"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace raytime
