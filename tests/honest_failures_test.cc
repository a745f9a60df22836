// Issue 47 "nothing absurd is accepted, no failure leaves a lie behind", end to end through the
// binary on the sample scene: resource limits (threads, memory, file descriptors) and crashes end
// with a record that names the cause and one exit status per class; paths are resolved as the
// operating system and a shell resolve them; the work directory may not be the image folder;
// names an export cannot hold are refused before any work; a shared cache entry is used only
// under its own key; a failed export names its own files as this run's; an image at twice its
// siblings' size has its intrinsics rescaled.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>

#include "core/atomic_file.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

std::string StageStatus(const json& summary, const std::string& id) {
  for (const json& stage : summary["stages"]) {
    if (stage["id"] == id) return stage.value("status", "");
  }
  return "";
}

class HonestFailuresTest : public TempDirTest {
 protected:
  HonestFailuresTest() : TempDirTest("honest") {}
  void SetUp() override {
    TempDirTest::SetUp();
    workdir_ = dir_ / "demo";
  }

  CommandResult Demo(const std::string& extra = "", const std::string& environment = "") {
    return RunRaytime("run configs/demo.yaml --workdir " + workdir_.string() + " " + extra,
                      environment);
  }
  // `raytime ARGS` under `limits` (a bash ulimit command), from the source directory.
  CommandResult Limited(const std::string& limits, const std::string& args) {
    return RunShell(std::string("cd ") + RAYTIME_SOURCE_DIR + " && bash -c '" + limits + "; exec " +
                    RAYTIME_BINARY + " " + args + "' 2>&1");
  }

  fs::path workdir_;
};

// ---- 2. Resource limits and crashes.

// It segfaulted in TBB (exit 139) and left summary.json at "running".
TEST_F(HonestFailuresTest, AThreadCountBeyondTheBoundIsRefusedNotACrash) {
  const CommandResult result = Demo("--set refine.num_threads=100000");
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find("num_threads"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("at most 1024"), std::string::npos) << result.output;
}

// Under an address-space limit a run ended as std::bad_alloc, OpenCV's "Insufficient memory",
// "pthread_create has failed", or libgomp's exit 1 with summary.json left at "running" and no run
// page. Several limits, from scratch and for the refine stage alone (from a finished run), as where
// a run runs out depends on the machine: each run either finishes (exit 0, or 2 where the refined
// poses it kept are none) or ends with exit 3 (a resource) or 4 (crashed: libgomp's exit), a
// finished record naming memory or threads and the limit, and the run page; some run out.
void ExpectRecordNamesTheResource(const CommandResult& result, const fs::path& workdir,
                                  int* ran_out) {
  const json summary = ReadJsonFile(workdir / "summary.json");
  ASSERT_TRUE(summary.is_object()) << result.output;
  EXPECT_NE(summary["status"], "running") << result.output;
  if (result.exit_code == 0 || result.exit_code == 2) return;
  ++*ran_out;
  EXPECT_TRUE(result.exit_code == 3 || result.exit_code == 4) << result.output;
  EXPECT_TRUE(summary["status"] == "failed" || summary["status"] == "crashed") << summary;
  EXPECT_TRUE(summary["cause"] == "memory" || summary["cause"] == "threads") << summary;
  EXPECT_NE(summary.value("error", "").find("ulimit -v"), std::string::npos) << summary;
  EXPECT_TRUE(fs::exists(workdir / "report.html"));
}

TEST_F(HonestFailuresTest, RunningOutOfMemoryEndsWithARecordNamingIt) {
  const fs::path base = dir_ / "base";
  ASSERT_EQ(RunRaytime("run configs/demo.yaml --workdir " + base.string()).exit_code, 0);
  int ran_out = 0;
  for (const int kilobytes : {350000, 400000, 450000, 550000}) {
    SCOPED_TRACE("ulimit -v " + std::to_string(kilobytes));
    const std::string limit = "ulimit -v " + std::to_string(kilobytes);
    fs::remove_all(workdir_);
    ExpectRecordNamesTheResource(
        Limited(limit, "run configs/demo.yaml --workdir " + workdir_.string()), workdir_, &ran_out);
    fs::remove_all(workdir_);
    ASSERT_EQ(RunShell("cp -a " + base.string() + " " + workdir_.string()).exit_code, 0);
    ExpectRecordNamesTheResource(Limited(limit, "run configs/demo.yaml --workdir " +
                                                    workdir_.string() + " --set refine.preset=gnc"),
                                 workdir_, &ran_out);
  }
  EXPECT_GT(ran_out, 0);
}

// With few file descriptors it said "cannot write .../summary.json" or "cannot read the file".
TEST_F(HonestFailuresTest, RunningOutOfFileDescriptorsSaysSo) {
  int ran_out = 0;
  for (const int files : {5, 6, 7}) {
    SCOPED_TRACE("ulimit -n " + std::to_string(files));
    fs::remove_all(workdir_);
    const CommandResult result = Limited("ulimit -n " + std::to_string(files),
                                         "run configs/demo.yaml --workdir " + workdir_.string());
    if (result.exit_code == 0) continue;
    ++ran_out;
    EXPECT_EQ(result.exit_code, 3) << result.output;
    EXPECT_NE(result.output.find("too many open files"), std::string::npos) << result.output;
    EXPECT_NE(result.output.find("ulimit -n"), std::string::npos) << result.output;
  }
  EXPECT_GT(ran_out, 0);
}

// A crash inside the process (a library's SIGSEGV, an abort) left summary.json at "running" and
// no run page. Killed while it matches: recorded "crashed" by the waiting parent, exit 4, the
// earlier run's export moved aside as a failure moves it.
void ExpectCrashRecorded(const fs::path& workdir, int signal) {
  const std::string log = (workdir.parent_path() / "crash.log").string();
  const std::string command = std::string("cd ") + RAYTIME_SOURCE_DIR + " && exec " +
                              RAYTIME_BINARY + " run configs/demo.yaml --workdir " +
                              workdir.string() + " --set matches.max_ratio=0.79 >" + log + " 2>&1";
  const pid_t parent = ::fork();
  ASSERT_GE(parent, 0);
  if (parent == 0) {
    ::execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // The run's own process is the one summary.json names, once it reaches the matches stage.
  int child = 0;
  for (int i = 0; i < 600 && child == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const json summary = ReadJsonFile(workdir / "summary.json");
    if (summary.is_object() && summary.value("stage", "") == "matches" &&
        summary.value("status", "") == "running") {
      child = summary.value("pid", 0);
    }
  }
  ASSERT_GT(child, 0) << ReadTextFile(log);
  ::kill(child, signal);
  int status = 0;
  ASSERT_EQ(::waitpid(parent, &status, 0), parent);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 4) << ReadTextFile(log);
  const json summary = ReadJsonFile(workdir / "summary.json");
  EXPECT_EQ(summary["status"], "crashed") << summary;
  EXPECT_EQ(summary["signal"], signal) << summary;
  EXPECT_EQ(summary["stage"], "matches") << summary;
  EXPECT_NE(summary.value("error", "").find("signal " + std::to_string(signal)), std::string::npos)
      << summary;
  EXPECT_TRUE(fs::exists(workdir / "report.html"));
  EXPECT_FALSE(fs::exists(workdir / "refined_transforms.json"));
  EXPECT_TRUE(fs::exists(workdir / "stale" / "refined_transforms.json"));
}

TEST_F(HonestFailuresTest, ASegfaultOrAnAbortIsRecordedAsACrash) {
  ASSERT_EQ(Demo().exit_code, 0);
  ExpectCrashRecorded(workdir_, SIGSEGV);
  ASSERT_EQ(Demo().exit_code, 0);
  ExpectCrashRecorded(workdir_, SIGABRT);
}

// ---- 3. Paths.

// Reached through a link at another depth, every file_path of refined_transforms.json dangled
// (computed from the link's path).
TEST_F(HonestFailuresTest, TransformsPathsOpenThroughASymlinkedWorkdir) {
  const fs::path real = dir_ / "a" / "b" / "c" / "work";
  fs::create_directories(real);
  fs::create_directory_symlink(real, dir_ / "link");
  workdir_ = dir_ / "link";
  ASSERT_EQ(Demo().exit_code, 0);
  const json transforms = ReadJsonFile(workdir_ / "refined_transforms.json");
  ASSERT_FALSE(transforms["frames"].empty());
  for (const json& frame : transforms["frames"]) {
    const std::string path = frame["file_path"];
    EXPECT_TRUE(fs::exists(workdir_ / path)) << path;
  }
}

// `--workdir '~/wk'` wrote into a literal ./~/wk; `workdir: ~/wk` and dataset.root=~/ds alike.
TEST_F(HonestFailuresTest, ATildeIsExpandedAsAShellWould) {
  CopySampleScene(dir_ / "ds");
  const std::string home = "HOME=" + dir_.string();
  const CommandResult flag =
      RunRaytime("run configs/demo.yaml --workdir '~/wk' --set 'dataset.root=~/ds'", home);
  ASSERT_EQ(flag.exit_code, 0) << flag.output;
  EXPECT_TRUE(fs::exists(dir_ / "wk" / "refined_transforms.json"));
  EXPECT_FALSE(fs::exists(fs::path(RAYTIME_SOURCE_DIR) / "~"));
  std::string yaml = ReadTextFile((fs::path(RAYTIME_SOURCE_DIR) / "configs/demo.yaml").string());
  yaml.replace(yaml.find("root: data/sample/fountain-P11"), 30, "root: ~/ds");
  yaml.replace(yaml.find("workdir: work/demo"), 18, "workdir: ~/wk2");
  WriteTextFileAtomically((dir_ / "pipeline.yaml").string(), yaml);
  const CommandResult file = RunRaytime("run " + (dir_ / "pipeline.yaml").string(), home);
  ASSERT_EQ(file.exit_code, 0) << file.output;
  EXPECT_TRUE(fs::exists(dir_ / "wk2" / "refined_transforms.json"));
}

// The image folder as the work directory: raytime read its own summary.json as an image ("image
// without a ground-truth camera: summary.json") and never said why.
TEST_F(HonestFailuresTest, TheImageFolderIsRefusedAsTheWorkDirectoryBeforeAnythingIsWritten) {
  const fs::path scene = CopySampleScene(dir_ / "ds");
  for (const fs::path& inside : {scene / "images", scene / "images" / "work"}) {
    const CommandResult result = RunRaytime("run configs/demo.yaml --workdir " + inside.string() +
                                            " --set dataset.root=" + scene.string());
    EXPECT_EQ(result.exit_code, 2) << result.output;
    EXPECT_NE(result.output.find("reads whole (the dataset's images)"), std::string::npos)
        << result.output;
    EXPECT_FALSE(fs::exists(scene / "images" / "summary.json"));
    EXPECT_FALSE(fs::exists(scene / "images" / ".raytime"));
    EXPECT_FALSE(fs::exists(scene / "images" / "work"));
  }
}

// An image name with whitespace was refused by the COLMAP export only after the whole solve.
TEST_F(HonestFailuresTest, ANameTheExportCannotHoldIsRefusedBeforeAnyWork) {
  const fs::path scene = CopySampleScene(dir_ / "ds");
  fs::rename(scene / "images" / "0003.jpg", scene / "images" / "00 03.jpg");
  fs::rename(scene / "gt_dense_cameras" / "0003.jpg.camera",
             scene / "gt_dense_cameras" / "00 03.jpg.camera");
  const CommandResult result = Demo("--set dataset.root=" + scene.string());
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find("'00 03.jpg'"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("colmap_binary"), std::string::npos) << result.output;
  const json summary = ReadJsonFile(workdir_ / "summary.json");
  EXPECT_EQ(StageStatus(summary, "dataset"), "ran");
  EXPECT_EQ(StageStatus(summary, "features"), "");
  // Formats that hold any name run.
  const CommandResult binary = Demo("--set dataset.root=" + scene.string() +
                                    " --set export.formats=[colmap_binary,transforms_json]");
  EXPECT_EQ(binary.exit_code, 0) << binary.output;
}

// ---- 4. The shared cache.

// Two entries swapped on disk (each record.json naming its own key): a run asking for seed 0 got
// seed 5's prior.h5, "taken from the cache".
TEST_F(HonestFailuresTest, ACacheEntryUnderAnotherKeysNameIsComputedAgain) {
  const fs::path cache = dir_ / "cache";
  const std::string cache_flag = " --cache-dir " + cache.string();
  workdir_ = dir_ / "seed0";
  ASSERT_EQ(Demo(cache_flag + " --set prior.seed=0").exit_code, 0);
  const json seed0 = ReadJsonFile(workdir_ / "summary.json");
  workdir_ = dir_ / "seed5";
  ASSERT_EQ(Demo(cache_flag + " --set prior.seed=5").exit_code, 0);
  const json seed5 = ReadJsonFile(workdir_ / "summary.json");
  std::string key0, key5;
  for (const json& stage : seed0["stages"]) {
    if (stage["id"] == "prior") key0 = stage["key"];
  }
  for (const json& stage : seed5["stages"]) {
    if (stage["id"] == "prior") key5 = stage["key"];
  }
  ASSERT_TRUE(fs::exists(cache / key0 / "output.h5"));
  ASSERT_TRUE(fs::exists(cache / key5 / "output.h5"));
  fs::rename(cache / key0, cache / "swap");
  fs::rename(cache / key5, cache / key0);
  fs::rename(cache / "swap", cache / key5);
  workdir_ = dir_ / "again";
  const CommandResult again = Demo(cache_flag + " --set prior.seed=0");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("was computed for another key"), std::string::npos) << again.output;
  const json summary = ReadJsonFile(workdir_ / "summary.json");
  EXPECT_EQ(StageStatus(summary, "prior"), "ran");
  EXPECT_EQ(summary["metrics"], seed0["metrics"]);
}

// ---- 6. Smaller.

// An export that failed on its second format in a new work directory called the files its first
// format had just written "written by an earlier run".
TEST_F(HonestFailuresTest, AnExportThatFailsMidwayCallsItsOwnFilesThisRuns) {
  fs::create_directories(workdir_ / "refined_transforms.json");
  const CommandResult result = Demo();
  EXPECT_EQ(result.exit_code, 2) << result.output;
  EXPECT_NE(result.output.find("a folder is where raytime writes this file"), std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("refined: this run wrote it before it stopped"), std::string::npos)
      << result.output;
  EXPECT_EQ(result.output.find("earlier run"), std::string::npos) << result.output;
}

// A same-aspect image at twice its siblings' size was refused by the Strecha reader ("image is
// 1536x1024 but the image list says 768x512") though docs/formats.md promised the rescale.
TEST_F(HonestFailuresTest, AnImageAtTwiceTheSizeHasItsIntrinsicsRescaled) {
  const fs::path scene = CopySampleScene(dir_ / "ds");
  const fs::path image = scene / "images" / "0003.jpg";
  const cv::Mat small = cv::imread(image.string());
  cv::Mat large;
  cv::resize(small, large, cv::Size(small.cols * 2, small.rows * 2), 0, 0, cv::INTER_CUBIC);
  ASSERT_TRUE(cv::imwrite(image.string(), large, {cv::IMWRITE_JPEG_QUALITY, 95}));
  const CommandResult result = Demo("--set dataset.root=" + scene.string());
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("intrinsics_rescaled"), std::string::npos) << result.output;
  const json transforms = ReadJsonFile(workdir_ / "refined_transforms.json");
  bool found = false;
  for (const json& frame : transforms["frames"]) {
    if (fs::path(frame["file_path"].get<std::string>()).filename() != "0003.jpg") continue;
    found = true;
    EXPECT_EQ(frame["w"], small.cols * 2);
    EXPECT_EQ(frame["raytime_verdict"], "held") << frame;
  }
  EXPECT_TRUE(found);
}

}  // namespace
}  // namespace raytime
