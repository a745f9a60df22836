// Issue 30 "Nothing wrong leaves", end to end through the binary on the sample scene: a full disk
// is an error that says so (not a crash), a prior in another convention is refused with the fix,
// one run at a time in a work directory, a failed run leaves no earlier run's poses under the
// names users train from, evaluation never blocks the export, transforms.json's file paths open,
// an intermediate damaged at its size is recomputed, and the smaller input mistakes are named.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <sys/mount.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "formats/colmap_model.h"
#include "formats/strecha.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

json ReadRunSummary(const fs::path& workdir) {
  std::ifstream in(workdir / "summary.json");
  return json::parse(in);
}

// The entry of stage `id` in summary.json's stages; an empty object when it did not run.
json StageEntry(const json& summary, const std::string& id) {
  for (const json& stage : summary["stages"]) {
    if (stage["id"] == id) return stage;
  }
  return json::object();
}

bool HasWarning(const json& summary, const std::string& code) {
  for (const json& warning : summary["warnings"]) {
    if (warning["code"] == code) return true;
  }
  return false;
}

class NothingWrongLeavesTest : public TempDirTest {
 protected:
  NothingWrongLeavesTest() : TempDirTest("leaves") {}
  void TearDown() override {
    if (mounted_) ::umount(mounted_path_.c_str());
    TempDirTest::TearDown();
  }

  std::string Demo(const std::string& workdir, const std::string& extra = "") {
    return "run configs/demo.yaml --workdir " + workdir + " " + extra;
  }

  bool mounted_ = false;
  std::string mounted_path_;
};

// The disk-full failure, injected: writes beyond RLIMIT_FSIZE fail with EFBIG (SIGXFSZ ignored,
// as a full disk gives ENOSPC without a signal). It crashed at exit in HDF5's cleanup (139).
TEST_F(NothingWrongLeavesTest, AFailingWriteIsAnErrorNamingTheFileNotACrash) {
  const fs::path workdir = dir_ / "demo";
  const CommandResult result = RunShell(std::string("cd ") + RAYTIME_SOURCE_DIR +
                                        " && bash -c \"trap '' XFSZ; ulimit -f 200; exec " +
                                        RAYTIME_BINARY + " " + Demo(workdir.string()) + "\" 2>&1");
  EXPECT_EQ(result.exit_code, 1) << result.output;
  EXPECT_NE(result.output.find((workdir / "features.h5").string() + ": cannot write"),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("File too large"), std::string::npos) << result.output;
  EXPECT_EQ(ReadRunSummary(workdir)["status"], "failed");
  EXPECT_FALSE(fs::exists(workdir / "features.h5"));
  EXPECT_TRUE(TemporaryFilesBelow(workdir).empty());
}

// A real full disk: a 9 MiB tmpfs holds the front end's files but not the refiner's. Needs the
// right to mount (root in CI); skipped elsewhere, the injected failure above runs everywhere.
TEST_F(NothingWrongLeavesTest, AFullDiskSaysSoInTheFeaturesAndTheRefineStage) {
  const fs::path mount = dir_ / "small";
  fs::create_directories(mount);
  if (::mount("tmpfs", mount.c_str(), "tmpfs", 0, "size=9m") != 0) {
    GTEST_SKIP() << "cannot mount a tmpfs here (not root, or not allowed)";
  }
  mounted_ = true;
  mounted_path_ = mount.string();
  const fs::path workdir = mount / "demo";
  const CommandResult result = RunRaytime(Demo(workdir.string()));
  EXPECT_EQ(result.exit_code, 3) << result.output;  // a resource ran out (issue 47)
  EXPECT_NE(result.output.find((workdir / "refine.h5").string() + ": cannot write"),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("no space left on device"), std::string::npos) << result.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(summary["status"], "failed");
  EXPECT_EQ(summary["cause"], "disk_space");
  EXPECT_EQ(summary["stage"], "refine");
  EXPECT_TRUE(TemporaryFilesBelow(workdir).empty());
  // Features do not fit beside the refiner's output's predecessors in 1 MiB.
  fs::remove_all(workdir);
  ASSERT_EQ(::umount(mount.c_str()), 0);
  ASSERT_EQ(::mount("tmpfs", mount.c_str(), "tmpfs", 0, "size=1m"), 0);
  const CommandResult small = RunRaytime(Demo(workdir.string()));
  EXPECT_EQ(small.exit_code, 3) << small.output;
  EXPECT_NE(small.output.find((workdir / "features.h5").string() + ": cannot write"),
            std::string::npos)
      << small.output;
  EXPECT_NE(small.output.find("no space left on device"), std::string::npos) << small.output;
}

// Someone wrote camera-to-world poses into a COLMAP model (world-to-camera): refined as given,
// the demo ended ok_with_warnings 84° off. The matches' own relative poses say so before any
// solve, and the named fix reads it right.
TEST_F(NothingWrongLeavesTest, APriorInAnotherConventionIsRefusedWithTheFix) {
  ImageSet images;
  PoseSet truth;
  ReadStrechaScene(std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11", &images, &truth);
  PoseSet inverted;
  for (const auto& [name, pose] : truth.world_from_cam) {
    inverted.world_from_cam[name] = pose.Inverse();
  }
  const fs::path model = dir_ / "camera_to_world_model";
  WriteColmapModelText(ToColmapModel(images, inverted), model.string());
  const fs::path workdir = dir_ / "demo";
  const std::string prior =
      " --set prior.source=file --set prior.format=colmap --set prior.path=" + model.string();
  const CommandResult refused = RunRaytime(Demo(workdir.string(), prior));
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("the prior looks like camera-to-world poses given where "
                                "world-to-camera ones were expected"),
            std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find("Set prior.convention=inverted"), std::string::npos)
      << refused.output;
  EXPECT_EQ(ReadRunSummary(workdir)["status"], "failed");
  EXPECT_FALSE(fs::exists(workdir / "refined_transforms.json"));

  const CommandResult fixed =
      RunRaytime(Demo(workdir.string(), prior + " --set prior.convention=inverted"));
  ASSERT_EQ(fixed.exit_code, 0) << fixed.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_LT(summary["metrics"]["refined"]["sim3"]["mean_rotation_deg"].get<double>(), 0.1);
  const json check = StageEntry(summary, "refine")["summary"]["prior_convention"];
  ASSERT_TRUE(check.is_object()) << summary.dump();
  EXPECT_TRUE(check["checked"].get<bool>());
  EXPECT_FALSE(check["refused"].get<bool>());
  EXPECT_LT(check["scores"][0]["median_rotation_error_deg"].get<double>(), 0.5) << check.dump();
}

TEST_F(NothingWrongLeavesTest, ASecondRunInTheSameWorkDirectoryIsRefused) {
  const fs::path workdir = dir_ / "demo";
  fs::create_directories(workdir / ".raytime");
  // A run in progress holds the lock (here: this test, as pid 4242 says to the message).
  const int fd = ::open((workdir / ".raytime" / "run.lock").c_str(), O_CREAT | O_RDWR, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  ASSERT_EQ(::write(fd, "4242", 4), 4);
  const CommandResult second = RunRaytime(Demo(workdir.string()));
  EXPECT_EQ(second.exit_code, 2) << second.output;
  EXPECT_NE(second.output.find("another raytime run (pid 4242) is using this work directory"),
            std::string::npos)
      << second.output;
  EXPECT_FALSE(fs::exists(workdir / "summary.json"));
  ::close(fd);  // the run ended: the next one goes ahead
  const CommandResult third = RunRaytime(Demo(workdir.string()));
  EXPECT_EQ(third.exit_code, 0) << third.output;
}

TEST_F(NothingWrongLeavesTest, AFailedRunMovesAnEarlierRunsExportsAside) {
  const fs::path workdir = dir_ / "demo";
  ASSERT_EQ(RunRaytime(Demo(workdir.string())).exit_code, 0);
  ASSERT_TRUE(fs::exists(workdir / "refined_transforms.json"));
  // The same work directory, now with a prior the refiner refuses.
  const CommandResult failed =
      RunRaytime(Demo(workdir.string(), "--set prior.convention=inverted"));
  EXPECT_EQ(failed.exit_code, 2) << failed.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(summary["status"], "failed");
  EXPECT_FALSE(fs::exists(workdir / "refined"));
  EXPECT_FALSE(fs::exists(workdir / "refined_transforms.json"));
  EXPECT_TRUE(fs::exists(workdir / "stale" / "refined" / "images.txt"));
  EXPECT_TRUE(fs::exists(workdir / "stale" / "refined_transforms.json"));
  EXPECT_EQ(summary["stale_outputs_moved"], json::array({"refined", "refined_transforms.json"}));
  // The run's page is written on failure too, and says so with the error.
  const std::string page = ReadTextFile((workdir / "report.html").string());
  EXPECT_NE(page.find("Status: <b>failed</b>"), std::string::npos);
  EXPECT_NE(page.find("convention"), std::string::npos);
  // Back to the working options: the export is written again (not skipped as unchanged).
  ASSERT_EQ(RunRaytime(Demo(workdir.string())).exit_code, 0);
  EXPECT_TRUE(fs::exists(workdir / "refined_transforms.json"));
}

// A rerun whose export no longer writes a format left the earlier run's file beside the new
// ones: a trainer reading it got the poses of other options.
TEST_F(NothingWrongLeavesTest, AnExportARerunNoLongerWritesIsMovedAside) {
  const fs::path workdir = dir_ / "demo";
  ASSERT_EQ(RunRaytime(Demo(workdir.string())).exit_code, 0);
  ASSERT_TRUE(fs::exists(workdir / "refined_transforms.json"));
  const CommandResult rerun =
      RunRaytime(Demo(workdir.string(), "--set export.formats=[colmap_text]"));
  ASSERT_EQ(rerun.exit_code, 0) << rerun.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(summary["status"], "ok");
  EXPECT_TRUE(fs::exists(workdir / "refined" / "images.txt"));
  EXPECT_FALSE(fs::exists(workdir / "refined_transforms.json"));
  EXPECT_TRUE(fs::exists(workdir / "stale" / "refined_transforms.json"));
  EXPECT_EQ(summary["stale_outputs_moved"], json::array({"refined_transforms.json"}));
}

// Two images: the refiner solves their pair, but a Sim(3) fit of two centres is not defined, and
// evaluate's failure used to stop the run before export.
TEST_F(NothingWrongLeavesTest, AFailingEvaluationDoesNotKeepThePosesFromTheExport) {
  const fs::path sample = fs::path(RAYTIME_SOURCE_DIR) / "data/sample/fountain-P11";
  const fs::path scene = dir_ / "two";
  fs::create_directories(scene / "images");
  fs::create_directories(scene / "gt_dense_cameras");
  for (const std::string name : {"0004.jpg", "0005.jpg"}) {
    fs::copy_file(sample / "images" / name, scene / "images" / name);
    fs::copy_file(sample / "gt_dense_cameras" / (name + ".camera"),
                  scene / "gt_dense_cameras" / (name + ".camera"));
  }
  const fs::path workdir = dir_ / "run";
  const CommandResult result =
      RunRaytime(Demo(workdir.string(), "--set dataset.root=" + scene.string()));
  EXPECT_EQ(result.exit_code, 0) << result.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(summary["status"], "ok_with_warnings");
  EXPECT_TRUE(HasWarning(summary, "stage_failed")) << summary["warnings"].dump();
  EXPECT_EQ(StageEntry(summary, "evaluate").value("status", ""), "failed");
  EXPECT_EQ(StageEntry(summary, "export").value("status", ""), "ran");
  EXPECT_TRUE(fs::exists(workdir / "refined_transforms.json"));
}

// One image's focal length 1.5x too long: the solve kept every pair consistent by moving that
// camera 3.5 m (the others 0.5 m), and the run ended ok with it exported. It is named by name and
// left out of the export.
TEST_F(NothingWrongLeavesTest, AFrameWithWrongIntrinsicsIsNamedAndLeftOut) {
  const fs::path sample = fs::path(RAYTIME_SOURCE_DIR) / "data/sample/fountain-P11";
  const fs::path scene = dir_ / "scene";
  fs::copy(sample, scene, fs::copy_options::recursive);
  const fs::path camera = scene / "gt_dense_cameras" / "0005.jpg.camera";
  std::string contents;
  {
    std::ifstream in(camera);
    contents.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // K's first two rows: fx 689.87 -> 1034.805, fy 691.03999999999996 -> 1036.56.
  const size_t fx = contents.find("689.87 "), fy = contents.find("691.03999999999996 ");
  ASSERT_NE(fx, std::string::npos);
  ASSERT_NE(fy, std::string::npos);
  contents.replace(fy, 18, "1036.56");
  contents.replace(fx, 6, "1034.805");
  std::ofstream(camera) << contents;
  const fs::path workdir = dir_ / "run";
  const CommandResult result =
      RunRaytime(Demo(workdir.string(), "--set dataset.root=" + scene.string()));
  ASSERT_EQ(result.exit_code, 0) << result.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(summary["status"], "ok_with_warnings");
  bool named = false;
  for (const json& warning : summary["warnings"]) {
    if (warning["code"] == "frame_doubts") named = warning["images"] == json::array({"0005.jpg"});
  }
  EXPECT_TRUE(named) << summary["warnings"].dump();
  std::ifstream in(workdir / "refined_transforms.json");
  const json transforms = json::parse(in);
  EXPECT_EQ(transforms["frames"].size(), 10u);
  for (const json& frame : transforms["frames"]) {
    EXPECT_EQ(frame["file_path"].get<std::string>().find("0005.jpg"), std::string::npos);
  }
}

// Trainers resolve file_path from the transforms.json's own folder; it named images/NAME below a
// work directory that has no images.
TEST_F(NothingWrongLeavesTest, EveryFilePathOfTheExportedTransformsOpens) {
  const fs::path workdir = dir_ / "demo";
  ASSERT_EQ(RunRaytime(Demo(workdir.string())).exit_code, 0);
  std::ifstream in(workdir / "refined_transforms.json");
  const json transforms = json::parse(in);
  ASSERT_EQ(transforms["frames"].size(), 11u);
  for (const json& frame : transforms["frames"]) {
    const fs::path image = workdir / frame["file_path"].get<std::string>();
    EXPECT_TRUE(fs::is_regular_file(image)) << image;
    EXPECT_TRUE(std::ifstream(image).good()) << image;
  }
}

// Bytes changed in the middle of matches.h5, its size kept: every rerun failed on "missing
// dataset" with no hint. Its checksum no longer matches the one recorded, so it is recomputed.
TEST_F(NothingWrongLeavesTest, AnIntermediateDamagedAtItsSizeIsComputedAgain) {
  const fs::path workdir = dir_ / "demo";
  ASSERT_EQ(RunRaytime(Demo(workdir.string())).exit_code, 0);
  const fs::path matches = workdir / "matches.h5";
  const auto size = fs::file_size(matches);
  {
    std::fstream file(matches, std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(static_cast<std::streamoff>(size / 2));
    const std::string garbage(4096, '\x5a');
    file.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
  }
  ASSERT_EQ(fs::file_size(matches), size);
  const CommandResult rerun = RunRaytime(Demo(workdir.string()));
  EXPECT_EQ(rerun.exit_code, 0) << rerun.output;
  EXPECT_NE(rerun.output.find("is not the file this stage wrote"), std::string::npos)
      << rerun.output;
  const json summary = ReadRunSummary(workdir);
  EXPECT_EQ(StageEntry(summary, "matches").value("status", ""), "ran");
  // Matching is deterministic: the recomputed file is the one the later stages used.
  EXPECT_EQ(StageEntry(summary, "refine").value("status", ""), "skipped");
}

TEST_F(NothingWrongLeavesTest, SmallerInputMistakesAreNamed) {
  // A key given twice: yaml-cpp kept the first silently.
  const fs::path pipeline = dir_ / "twice.yaml";
  std::ofstream(pipeline) << "dataset: {format: strecha, root: data/sample/fountain-P11}\n"
                             "stages:\n"
                             "  - prior:\n"
                             "      source: perturb\n"
                             "      level_deg: 4\n"
                             "      level_deg: 8\n";
  const CommandResult twice =
      RunRaytime("run " + pipeline.string() + " --workdir " + (dir_ / "w").string());
  EXPECT_EQ(twice.exit_code, 2) << twice.output;
  EXPECT_NE(twice.output.find(pipeline.string() +
                              ":6: key 'level_deg' appears twice in one mapping (first at line 5)"),
            std::string::npos)
      << twice.output;

  // An empty --workdir (an unset shell variable) wrote into the pipeline's own.
  const CommandResult empty = RunRaytime("run configs/demo.yaml --workdir \"\"");
  EXPECT_EQ(empty.exit_code, 2) << empty.output;
  EXPECT_NE(empty.output.find("--workdir is empty"), std::string::npos) << empty.output;

  // A value out of range given by --set is blamed on the --set, not on the pipeline's line.
  const CommandResult range = RunRaytime(Demo((dir_ / "r").string(), "--set prior.level_deg=-3"));
  EXPECT_EQ(range.exit_code, 2) << range.output;
  EXPECT_NE(range.output.find("--set prior.level_deg"), std::string::npos) << range.output;
  EXPECT_EQ(range.output.find("configs/demo.yaml:"), std::string::npos) << range.output;
  EXPECT_FALSE(fs::exists(dir_ / "r" / "features.h5"));

  // An empty prior.path is refused before any work is done.
  const CommandResult no_path =
      RunRaytime(Demo((dir_ / "p").string(), "--set prior.source=file --set prior.path=\"\""));
  EXPECT_EQ(no_path.exit_code, 2) << no_path.output;
  EXPECT_NE(no_path.output.find("prior.path is not set"), std::string::npos) << no_path.output;
  EXPECT_FALSE(fs::exists(dir_ / "p" / "features.h5"));
}

}  // namespace
}  // namespace raytime
