// Cost of matching against the number of frames of a long sequence (issue 10, "Prior-guided
// pairs"; a benchmark, not a test): for the first N frames of a sequence, prior-guided pairs
// (pipelines/pair_selection.h, the matches stage's choice) against exhaustive pairs, both matched
// and verified by the front end in this one process, so every time is measured in the same run.
// Exhaustive matching is run only while it has at most --max-exhaustive-pairs pairs; beyond, its
// row gives the pair count alone.
//
//   pair_scaling --images W/dataset.h5 --features W/features.h5 --poses W/prior.h5
//       [--pose-set prior] [--frames 25,50,100,200,400] [--max-exhaustive-pairs 5000]
//       [--neighbors 10] [--window 0] [--json OUT]
//
// bench/prior_pairs_scaling.sh makes the inputs from the Record3D desk capture and runs it.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "bench/bench_main.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/timing.h"
#include "frontend/matching.h"
#include "pipelines/pair_selection.h"

namespace raytime {
namespace {

struct Row {
  int frames = 0;
  int64_t prior_pairs = 0, exhaustive_pairs = 0;
  int prior_verified = 0, exhaustive_verified = -1;
  double selection_seconds = 0, prior_seconds = 0, exhaustive_seconds = -1;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(Row, frames, prior_pairs, exhaustive_pairs, prior_verified,
                                   exhaustive_verified, selection_seconds, prior_seconds,
                                   exhaustive_seconds)

std::string Format(const char* format, double value) {
  char text[32];
  std::snprintf(text, sizeof(text), format, value);
  return text;
}

int Main(int argc, char** argv) {
  CLI::App app{"Matching cost against the number of frames: prior-guided vs exhaustive pairs"};
  std::string images_path, features_path, poses_path, pose_set = "prior", json_path;
  std::vector<int> frames = {25, 50, 100, 200, 400};
  int64_t max_exhaustive_pairs = 5000;
  PriorPairOptions selection;
  app.add_option("--images", images_path, "HDF5 file with the image list")->required();
  app.add_option("--features", features_path, "HDF5 file with the features")->required();
  app.add_option("--poses", poses_path, "HDF5 file with the pose set choosing pairs")->required();
  app.add_option("--pose-set", pose_set, "Pose set name");
  app.add_option("--frames", frames, "Frame counts (the first N frames)")->delimiter(',');
  app.add_option("--max-exhaustive-pairs", max_exhaustive_pairs,
                 "Run exhaustive matching only up to this many pairs");
  app.add_option("--neighbors", selection.prior_neighbors, "prior_neighbors");
  app.add_option("--window", selection.prior_window, "prior_window");
  app.add_option("--json", json_path, "Write the rows as JSON");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(spdlog::level::warn);

  const ImageSet all_images = Hdf5Reader(images_path).ReadImages();
  const std::vector<ImageFeatures> all_features = Hdf5Reader(features_path).ReadFeatures();
  const PoseSet poses = Hdf5Reader(poses_path).ReadPoseSet(pose_set);
  MatchingOptions matching;  // the matches stage's defaults (guided matching on)

  std::vector<Row> rows;
  std::printf("%7s %12s %10s %10s %12s %10s %10s %11s %11s\n", "frames", "prior_pairs", "prior_s",
              "s/pair", "exh_pairs", "exh_s", "s/pair", "prior/exh", "select_s");
  for (const int n : frames) {
    if (n < 2 || n > static_cast<int>(all_images.images.size())) continue;
    ImageSet images = all_images;
    images.images.resize(n);
    const std::vector<ImageFeatures> features(all_features.begin(), all_features.begin() + n);
    Row row;
    row.frames = n;
    auto start = std::chrono::steady_clock::now();
    const auto prior_pairs =
        SelectPriorPairs(PairSelectionViews(images, poses), selection, nullptr);
    row.selection_seconds = SecondsSince(start);
    row.prior_pairs = static_cast<int64_t>(prior_pairs.size());
    std::vector<PairMatches> out;
    start = std::chrono::steady_clock::now();
    row.prior_verified =
        MatchImagePairs(images, features, matching, prior_pairs, &out).num_verified_pairs;
    row.prior_seconds = SecondsSince(start);
    row.exhaustive_pairs = static_cast<int64_t>(n) * (n - 1) / 2;
    if (row.exhaustive_pairs <= max_exhaustive_pairs) {
      start = std::chrono::steady_clock::now();
      row.exhaustive_verified = MatchImages(images, features, matching, &out).num_verified_pairs;
      row.exhaustive_seconds = SecondsSince(start);
    }
    const bool exh = row.exhaustive_seconds >= 0;
    std::printf("%7d %12lld %10.1f %10.3f %12lld %10s %10s %11s %11.3f\n", n,
                static_cast<long long>(row.prior_pairs), row.prior_seconds,
                row.prior_seconds / std::max<int64_t>(1, row.prior_pairs),
                static_cast<long long>(row.exhaustive_pairs),
                exh ? Format("%.1f", row.exhaustive_seconds).c_str() : "-",
                exh ? Format("%.3f", row.exhaustive_seconds / row.exhaustive_pairs).c_str() : "-",
                exh ? Format("%.3f", row.prior_seconds / row.exhaustive_seconds).c_str() : "-",
                row.selection_seconds);
    std::fflush(stdout);
    rows.push_back(row);
  }
  if (!json_path.empty()) std::ofstream(json_path) << nlohmann::json(rows).dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  return raytime::BenchMain("pair_scaling", raytime::Main, argc, argv);
}
