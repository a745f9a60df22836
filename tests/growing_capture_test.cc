// Issue 34, a capture that grows: the main job rerun in the same work directory after frames were
// added, removed or replaced extracts features only for the new content, matches only the pairs
// that involve it and gives what a fresh run on the same images gives (features, matches and poses
// bit-identical; poses within 0.01° when the solve starts from the previous solution,
// refine.warm_start). Nothing whose content changed is reused.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/geometry.h"
#include "core/hdf5_store.h"
#include "tests/raytime_command.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

json ReadJson(const fs::path& path) {
  std::ifstream in(path);
  return json::parse(in);
}

// The summary of stage `id` in a run's summary.json.
json StageSummary(const json& run, const std::string& id) {
  for (const json& stage : run["stages"]) {
    if (stage["id"] == id) return stage;
  }
  ADD_FAILURE() << "no stage " << id;
  return json();
}

class GrowingCaptureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("raytime_growing_capture_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    scene_ = CopySampleScene(dir_ / "scene");
    aside_ = dir_ / "aside";
    fs::create_directories(aside_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The demo on the scene as it is now, in `workdir`; its summary.json. A smaller feature budget
  // keeps the five runs quick; nothing here depends on it.
  json Run(const fs::path& workdir, const std::string& more_options = "") {
    const CommandResult result = RunRaytime("run configs/demo.yaml --workdir " + workdir.string() +
                                            " --set dataset.root=" + scene_.string() +
                                            " --set features.max_features=2048 " + more_options);
    EXPECT_EQ(result.exit_code, 0) << result.output;
    return ReadJson(workdir / "summary.json");
  }

  // A frame (its image and its camera file) out of the scene, or back.
  void Remove(const std::string& name) {
    fs::rename(scene_ / "images" / name, aside_ / name);
    fs::rename(scene_ / "gt_dense_cameras" / (name + ".camera"), aside_ / (name + ".camera"));
  }
  void Restore(const std::string& name) {
    fs::rename(aside_ / name, scene_ / "images" / name);
    fs::rename(aside_ / (name + ".camera"), scene_ / "gt_dense_cameras" / (name + ".camera"));
  }

  // Features, matches and refined poses of two runs over the same images: the first two
  // bit-identical, the poses within max_rotation_deg (0: bit-identical too).
  void ExpectSameResults(const fs::path& incremental, const fs::path& fresh,
                         double max_rotation_deg) {
    const ImageSet images = Hdf5Reader((incremental / "dataset.h5").string()).ReadImages();
    ASSERT_EQ(images.images.size(),
              Hdf5Reader((fresh / "dataset.h5").string()).ReadImages().images.size());
    const auto a_features = Hdf5Reader((incremental / "features.h5").string()).ReadFeatures();
    const auto b_features = Hdf5Reader((fresh / "features.h5").string()).ReadFeatures();
    ASSERT_EQ(a_features.size(), b_features.size());
    for (size_t i = 0; i < a_features.size(); ++i) {
      EXPECT_EQ(a_features[i].keypoints, b_features[i].keypoints) << images.images[i].name;
      EXPECT_EQ(a_features[i].descriptors, b_features[i].descriptors) << images.images[i].name;
    }
    const auto a_pairs = Hdf5Reader((incremental / "matches.h5").string()).ReadMatches();
    const auto b_pairs = Hdf5Reader((fresh / "matches.h5").string()).ReadMatches();
    ASSERT_EQ(a_pairs.size(), b_pairs.size());
    for (size_t p = 0; p < a_pairs.size(); ++p) {
      EXPECT_EQ(a_pairs[p].image1, b_pairs[p].image1);
      EXPECT_EQ(a_pairs[p].image2, b_pairs[p].image2);
      EXPECT_EQ(a_pairs[p].matches, b_pairs[p].matches);
      EXPECT_EQ(a_pairs[p].geometry.inlier_matches, b_pairs[p].geometry.inlier_matches);
    }
    const PoseSet a = Hdf5Reader((incremental / "refine.h5").string()).ReadPoseSet("refined");
    const PoseSet b = Hdf5Reader((fresh / "refine.h5").string()).ReadPoseSet("refined");
    ASSERT_EQ(a.size(), b.size());
    for (const auto& [name, pose] : a.world_from_cam) {
      ASSERT_TRUE(b.Has(name)) << name;
      const Rigid3& other = b.world_from_cam.at(name);
      if (max_rotation_deg == 0) {
        EXPECT_EQ(pose.rotation.coeffs(), other.rotation.coeffs()) << name;
        EXPECT_EQ(pose.translation, other.translation) << name;
      } else {
        EXPECT_LT(RotationDistance(pose.rotation, other.rotation) * 180 / M_PI, max_rotation_deg)
            << name;
      }
    }
  }

  // What a run's features and matches stages computed and reused.
  static void ExpectWork(const json& run, int extracted, int reused_images, int matched,
                         int reused_pairs) {
    const json features = StageSummary(run, "features")["summary"];
    EXPECT_EQ(features["num_images_extracted"], extracted);
    EXPECT_EQ(features["num_images_reused"], reused_images);
    const json matches = StageSummary(run, "matches")["summary"];
    EXPECT_EQ(matches["num_pairs_matched"], matched);
    EXPECT_EQ(matches["num_pairs_reused"], reused_pairs);
  }

  fs::path dir_, scene_, aside_;
};

TEST_F(GrowingCaptureTest, OnlyNewContentIsComputedAndTheResultIsAFreshRuns) {
  const fs::path images = scene_ / "images";
  const fs::path workdir = dir_ / "run";
  // Nine frames first ...
  Remove("0009.jpg");
  Remove("0010.jpg");
  json run = Run(workdir);
  ExpectWork(run, 9, 0, 36, 0);

  // ... then two more: only they are read, only their 19 pairs matched, and (asked for) the
  // solve's finish starts from the nine frames' solution.
  Restore("0009.jpg");
  Restore("0010.jpg");
  run = Run(workdir, "--set refine.warm_start=true");
  EXPECT_EQ(StageSummary(run, "features")["summary"]["num_images"], 11);
  EXPECT_EQ(StageSummary(run, "matches")["summary"]["num_pairs"], 55);
  ExpectWork(run, 2, 9, 19, 36);
  bool finish_warm = false;
  const json refine = StageSummary(run, "refine")["summary"];
  for (const json& pass : refine["passes"]) {
    const int warm_images = pass["ray_time_init"]["num_images_from_earlier_run"];
    if (pass["name"] == "finish") {
      finish_warm = true;
      EXPECT_EQ(warm_images, 9);
      EXPECT_GT(pass["ray_time_init"]["num_ray_times_from_earlier_run"], 0);
    } else {
      EXPECT_EQ(warm_images, 0) << pass["name"] << ": only the all-match finish starts warm";
    }
  }
  EXPECT_TRUE(finish_warm);
  Run(dir_ / "fresh11");
  ExpectSameResults(workdir, dir_ / "fresh11", 0.01);

  // A frame removed: nothing is computed again, and nothing of it is left.
  Remove("0003.jpg");
  ExpectWork(Run(workdir), 0, 10, 0, 45);
  EXPECT_EQ(Hdf5Reader((workdir / "dataset.h5").string()).ReadImages().Find("0003.jpg"), -1);
  EXPECT_FALSE(Hdf5Reader((workdir / "refine.h5").string()).ReadPoseSet("refined").Has("0003.jpg"));
  Run(dir_ / "fresh10");
  ExpectSameResults(workdir, dir_ / "fresh10", 0);

  // A frame replaced under the same name (saved again at another JPEG quality): its features and
  // its nine pairs are computed again, not taken from the earlier run.
  const cv::Mat replaced = cv::imread((images / "0005.jpg").string());
  ASSERT_FALSE(replaced.empty());
  ASSERT_TRUE(
      cv::imwrite((images / "0005.jpg").string(), replaced, {cv::IMWRITE_JPEG_QUALITY, 80}));
  ExpectWork(Run(workdir), 1, 9, 9, 36);
  fs::remove_all(dir_ / "fresh10");
  Run(dir_ / "fresh10");
  ExpectSameResults(workdir, dir_ / "fresh10", 0);
}

}  // namespace
}  // namespace raytime
