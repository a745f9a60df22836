// Which nearest-neighbour matcher the front end uses, by measurement (issue 3; not a test).
//
//   matcher_bench [--scene DIR] [--image1 NAME] [--image2 NAME] [--max-features N] [--repeats R]
//
// Extracts SIFT (front-end defaults) from two images of a Strecha-layout scene and matches them
// with the ratio test (0.8) and mutual check by: the front end's VNNI byte kernel (where the CPU
// has it), its AVX2 kernel, its portable cv::gemm kernel, cv::BFMatcher (float, k = 2, both
// directions) and cv::FlannBasedMatcher (4 k-d trees, 32 and 128 checks, both directions). One
// thread each (the front end parallelizes over pairs). Prints the best of R runs, the ratio to the
// first kernel and how many of its matches each method reproduces. All numbers come from this one
// run.
//
// Measured on fountain-P11 1536x1024 (0000.jpg/0001.jpg, 8192 keypoints each, shared 2-core
// Xeon with AVX-512, load ~20 from other builds): see the report of issue 3 and
// frontend/descriptor_matching.h.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/flann.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <string>

#include "bench/bench_main.h"
#include "core/error.h"
#include "frontend/descriptor_matching.h"
#include "frontend/feature_extraction.h"
#include "frontend/image_reading.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

using MatchSet = std::set<std::pair<uint32_t, uint32_t>>;

MatchSet ToSet(const MatchList& matches) {
  MatchSet out;
  for (Eigen::Index k = 0; k < matches.rows(); ++k) out.emplace(matches(k, 0), matches(k, 1));
  return out;
}

// Ratio test, distance bound 0.7 and mutual check on OpenCV k = 2 results in both directions
// (distances are L2 between unit descriptors), as RatioTestMatches does.
MatchSet FromKnn(const std::vector<std::vector<cv::DMatch>>& ab,
                 const std::vector<std::vector<cv::DMatch>>& ba, double ratio) {
  const auto best = [&](const std::vector<cv::DMatch>& k) -> int {
    if (k.empty()) return -1;
    const double second = k.size() > 1 ? k[1].distance : std::sqrt(2.0);
    return k[0].distance < 0.7 && k[0].distance < ratio * second ? k[0].trainIdx : -1;
  };
  MatchSet out;
  for (size_t i = 0; i < ab.size(); ++i) {
    const int j = best(ab[i]);
    if (j >= 0 && best(ba[j]) == static_cast<int>(i)) out.emplace(i, j);
  }
  return out;
}

double Time(int repeats, const std::function<void()>& run) {
  double best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    run();
    best = std::min(
        best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  return best;
}

int Main(int argc, char** argv) {
  std::string scene = std::string(RAYTIME_SOURCE_DIR) + "/../shared/data/strecha/fountain-P11";
  std::string name1 = "0000.jpg", name2 = "0001.jpg";
  FeatureExtractionOptions extraction;
  int repeats = 3;
  for (int a = 1; a + 1 < argc; a += 2) {
    const std::string key = argv[a], value = argv[a + 1];
    if (key == "--scene")
      scene = value;
    else if (key == "--image1")
      name1 = value;
    else if (key == "--image2")
      name2 = value;
    else if (key == "--max-features")
      extraction.max_features = std::stoi(value);
    else if (key == "--repeats")
      repeats = std::stoi(value);
    else
      throw InputError("unknown argument " + key);
  }
  const auto load = [&](const std::string& name) {
    const std::string path = (fs::path(scene) / "images" / name).string();
    const cv::Mat gray = ReadImage(path, cv::IMREAD_GRAYSCALE);
    return ExtractSift(gray, extraction).descriptors;
  };
  const ByteDescriptors a_bytes = load(name1), b_bytes = load(name2);
  // The OpenCV matchers work on unit-length floats.
  const FloatDescriptors a = NormalizeDescriptors(a_bytes), b = NormalizeDescriptors(b_bytes);
  cv::setNumThreads(1);
  std::printf("%s: %s (%ld) x %s (%ld), dim %ld, best of %d, 1 thread\n", scene.c_str(),
              name1.c_str(), static_cast<long>(a.rows()), name2.c_str(),
              static_cast<long>(b.rows()), static_cast<long>(a.cols()), repeats);

  const auto kernel = [&](MatchKernel which) {
    NeighborList ab, ba;
    FindNeighbors(a_bytes, b_bytes, which, &ab, &ba);
    return ToSet(RatioTestMatches(ab, ba, 0.8, 0.7, true));
  };
  const cv::Mat ma(a.rows(), a.cols(), CV_32F, const_cast<float*>(a.data()));
  const cv::Mat mb(b.rows(), b.cols(), CV_32F, const_cast<float*>(b.data()));
  const auto opencv = [&](cv::DescriptorMatcher& matcher_ab, cv::DescriptorMatcher& matcher_ba) {
    std::vector<std::vector<cv::DMatch>> ab, ba;
    matcher_ab.knnMatch(ma, mb, ab, 2);
    matcher_ba.knnMatch(mb, ma, ba, 2);
    return FromKnn(ab, ba, 0.8);
  };

  struct Row {
    std::string name;
    double seconds;
    MatchSet matches;
  };
  std::vector<Row> rows;
  const auto measure = [&](const std::string& name, const std::function<MatchSet()>& run) {
    MatchSet result;
    const double seconds = Time(repeats, [&] { result = run(); });
    rows.push_back({name, seconds, result});
  };
  if (CpuHasVnni()) measure("vnni kernel", [&] { return kernel(MatchKernel::kVnni); });
  if (CpuHasAvx2Fma()) measure("avx2 kernel", [&] { return kernel(MatchKernel::kAvx2); });
  measure("gemm kernel (cv::gemm)", [&] { return kernel(MatchKernel::kGemm); });
  measure("cv::BFMatcher float", [&] {
    cv::BFMatcher ab(cv::NORM_L2), ba(cv::NORM_L2);
    return opencv(ab, ba);
  });
  for (const int checks : {32, 128}) {
    measure("FLANN kd4 checks " + std::to_string(checks), [&] {
      cv::FlannBasedMatcher ab(cv::makePtr<cv::flann::KDTreeIndexParams>(4),
                               cv::makePtr<cv::flann::SearchParams>(checks));
      cv::FlannBasedMatcher ba(cv::makePtr<cv::flann::KDTreeIndexParams>(4),
                               cv::makePtr<cv::flann::SearchParams>(checks));
      return opencv(ab, ba);
    });
  }

  const MatchSet& exact = rows.front().matches;
  std::printf("%-26s %9s %8s %9s %14s\n", "method", "seconds", "ratio", "matches", "exact matches");
  for (const Row& row : rows) {
    int common = 0;
    for (const auto& m : row.matches) common += exact.count(m);
    std::printf("%-26s %9.3f %8.2f %9zu %8d/%zu\n", row.name.c_str(), row.seconds,
                row.seconds / rows.front().seconds, row.matches.size(), common, exact.size());
  }
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  return raytime::BenchMain("matcher_bench", raytime::Main, argc, argv);
}
