// Issue 49: a folder laid out as ns-process-data lays one out, refined in place by
// configs/nerfstudio.yaml with the raytime binary: WORKDIR/transforms.json holds every key of the
// input in its order with only transform_matrix changed (and raytime_ keys added), in the input's
// world; every path resolves from WORKDIR to the folder's files; the folder is left as it was.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "evaluate/pose_errors.h"
#include "formats/nerfstudio.h"
#include "formats/strecha.h"
#include "raytime_command.h"
#include "temp_dir.h"
#include "tests/capture_fixtures.h"

namespace raytime {
namespace {

namespace fs = std::filesystem;
using nlohmann::ordered_json;

// Every file below `root` with its contents, to see that nothing there changed.
std::map<std::string, std::string> FilesWithContents(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    if (entry.is_regular_file()) files[entry.path().string()] = ReadTextFile(entry.path().string());
  }
  return files;
}

double MeanRotationDeg(const PoseSet& estimate, const PoseSet& truth,
                       const std::string& alignment) {
  PoseErrorOptions options;
  options.alignment = alignment;
  return ComputePoseErrors(estimate, truth, options).mean_rotation_deg;
}

TEST(NerfstudioInPlace, AFolderIsRefinedWithOnlyItsPosesChanged) {
  TempDir dir("nerfstudio_in_place");
  const fs::path folder = dir.path() / "capture";
  const fs::path work = dir.path() / "work";
  const Rigid3 applied(Eigen::Quaterniond(Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX())),
                       Eigen::Vector3d(0.25, 0, -1));
  const fixtures::Capture capture = fixtures::SampleCapture();
  fixtures::WriteNerfstudio(capture, folder.string(), applied);
  const std::map<std::string, std::string> before_files = FilesWithContents(folder);

  const CommandResult run =
      RunRaytime("run configs/nerfstudio.yaml --workdir " + work.string() +
                 " --set dataset.root=" + folder.string() +
                 " --set features.max_features=2048 --set features.first_octave=0");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(FilesWithContents(folder), before_files);  // nothing of the user's touched

  const ordered_json before =
      ordered_json::parse(before_files.at((folder / "transforms.json").string()));
  const ordered_json after = ordered_json::parse(ReadTextFile((work / "transforms.json").string()));
  ASSERT_FALSE(after.contains("raytime_left_out_frames")) << after.dump(1);
  for (const auto& [key, value] : before.items()) {
    if (key != "frames") EXPECT_EQ(after[key], value) << key;
  }
  ASSERT_EQ(after["frames"].size(), before["frames"].size());
  for (size_t i = 0; i < before["frames"].size(); ++i) {
    ordered_json frame = after["frames"][i];
    EXPECT_NE(frame["transform_matrix"], before["frames"][i]["transform_matrix"]);
    EXPECT_EQ(frame["raytime_verdict"], "held") << i;
    EXPECT_GT(frame["raytime_rotation_sigma_deg"].get<double>(), 0) << i;
    for (const char* key : {"file_path", "depth_file_path", "mask_path"}) {
      const std::string path = frame[key];
      EXPECT_TRUE(fs::equivalent(work / path, folder / path)) << path;
    }
    for (const char* key : {"transform_matrix", "raytime_verdict", "raytime_verdict_reason",
                            "raytime_rotation_sigma_deg", "raytime_centre_sigma"}) {
      frame.erase(key);
    }
    ordered_json original = before["frames"][i];
    original.erase("transform_matrix");
    EXPECT_EQ(frame, original) << i;  // every other key, in its order
  }
  EXPECT_TRUE(fs::equivalent(work / "sparse_pc.ply", folder / "sparse_pc.ply"));

  // In the input's world (after its applied_transform), read as nerfstudio reads the file: the
  // refined shape is nearer the truth than the 2° prior, and the poses stay in that world (an
  // ignored applied_transform would be 90° off without alignment).
  PoseSet prior, refined, truth;
  ReadTransformsJson((folder / "transforms.json").string(), nullptr, &prior);
  ReadTransformsJson((work / "transforms.json").string(), nullptr, &refined);
  ImageSet images;
  PoseSet ground_truth;
  ReadStrechaScene(std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11", &images,
                   &ground_truth);
  for (size_t i = 0; i < images.images.size(); ++i) {
    truth.world_from_cam[fixtures::NerfstudioName(static_cast<int>(i))] =
        applied * ground_truth.world_from_cam.at(images.images[i].name);
  }
  EXPECT_LT(MeanRotationDeg(refined, truth, "sim3"), 0.5 * MeanRotationDeg(prior, truth, "sim3"));
  EXPECT_LT(MeanRotationDeg(refined, truth, "none"), MeanRotationDeg(prior, truth, "none"));
}

// The work directory is the folder: refused before anything is written (a failed run moves its
// stages' stale outputs aside, and the user's transforms.json is the export's output name).
TEST(NerfstudioInPlace, TheFolderItselfIsRefusedAsTheWorkDirectory) {
  TempDir dir("nerfstudio_in_place_self");
  const fs::path folder = dir.path() / "capture";
  fixtures::WriteNerfstudio(fixtures::SampleCapture(), folder.string(), Rigid3());
  const std::map<std::string, std::string> before_files = FilesWithContents(folder);
  const CommandResult run = RunRaytime("run configs/nerfstudio.yaml --workdir " + folder.string() +
                                       " --set dataset.root=" + folder.string());
  EXPECT_EQ(run.exit_code, 2) << run.output;
  EXPECT_NE(run.output.find("would write over this file"), std::string::npos) << run.output;
  EXPECT_EQ(FilesWithContents(folder), before_files);
  EXPECT_FALSE(fs::exists(folder / "summary.json"));
}

}  // namespace
}  // namespace raytime
