// Issue 47 "Nothing of the user's is lost", end to end through the binary on the sample scene: a
// file raytime did not write in a folder it writes whole (a user's notes, a trainer's state kept
// beside the export, the user's own cameras.txt) survives a rerun and a failed run, or the run
// refuses, naming it; a file name's escape sequences reach the terminal shown, not obeyed.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/atomic_file.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

void Write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

class UsersFilesTest : public TempDirTest {
 protected:
  UsersFilesTest() : TempDirTest("users_files") {}
  void SetUp() override {
    TempDirTest::SetUp();
    workdir_ = dir_ / "demo";
  }

  CommandResult Demo(const std::string& extra = "") {
    return RunRaytime("run configs/demo.yaml --workdir " + workdir_.string() +
                      " --set export.formats=[colmap_text,transforms_json,3dgs] " + extra);
  }

  // The user's files beside raytime's in the two kinds of export folder.
  void AddUsersFiles() {
    Write(workdir_ / "refined" / "notes.txt", "my notes");
    Write(workdir_ / "refined" / "trainer_state" / "step_100.ckpt", "state");
    Write(workdir_ / "3dgs" / "refined" / "my_split.txt", "0001.jpg");
  }

  void ExpectUsersFilesKept() {
    EXPECT_EQ(ReadTextFile((workdir_ / "refined" / "notes.txt").string()), "my notes");
    EXPECT_EQ(ReadTextFile((workdir_ / "refined" / "trainer_state" / "step_100.ckpt").string()),
              "state");
    EXPECT_EQ(ReadTextFile((workdir_ / "3dgs" / "refined" / "my_split.txt").string()), "0001.jpg");
  }

  fs::path workdir_;
};

// A rerun whose export writes again (its options changed) and nothing else: the stages before it
// are unchanged, so they are skipped.
constexpr char kExportAgain[] = "--set export.leave_out_doubted_images=false";

// They were deleted by the next run's export, with no log line.
TEST_F(UsersFilesTest, ARerunKeepsTheFilesRaytimeDidNotWrite) {
  ASSERT_EQ(Demo().exit_code, 0);
  AddUsersFiles();
  // What a trainer derived from this export (Inria's points3D.ply, downscaled images) would be
  // used instead of the next export's: moved aside, not kept, not deleted.
  const fs::path gs = workdir_ / "3dgs" / "refined";
  Write(gs / "sparse" / "0" / "points3D.ply", "from the earlier points");
  Write(gs / "images_2" / "0001.jpg", "downscaled");
  const CommandResult rerun = Demo(kExportAgain);
  ASSERT_EQ(rerun.exit_code, 0) << rerun.output;
  ExpectUsersFilesKept();
  EXPECT_TRUE(fs::exists(workdir_ / "refined" / "images.txt"));
  EXPECT_TRUE(fs::exists(gs / "transforms.json"));
  EXPECT_FALSE(fs::exists(gs / "sparse" / "0" / "points3D.ply"));
  EXPECT_FALSE(fs::exists(gs / "images_2"));
  const fs::path stale = workdir_ / "stale" / "3dgs" / "refined";
  EXPECT_EQ(ReadTextFile((stale / "sparse" / "0" / "points3D.ply").string()),
            "from the earlier points");
  EXPECT_EQ(ReadTextFile((stale / "images_2" / "0001.jpg").string()), "downscaled");
  EXPECT_NE(rerun.output.find("a trainer derived it from the earlier export"), std::string::npos);
}

// A file of the user's under a name raytime writes: the run refuses, naming it, and it stays.
TEST_F(UsersFilesTest, AFileOfTheUsersUnderANameRaytimeWritesStopsTheRunNamingIt) {
  ASSERT_EQ(Demo().exit_code, 0);
  Write(workdir_ / "refined" / "cameras.txt", "# my own cameras\n");
  const CommandResult rerun = Demo(kExportAgain);
  EXPECT_EQ(rerun.exit_code, 2) << rerun.output;
  EXPECT_NE(rerun.output.find((workdir_ / "refined" / "cameras.txt").string() +
                              " was not written by raytime"),
            std::string::npos)
      << rerun.output;
  EXPECT_EQ(ReadTextFile((workdir_ / "refined" / "cameras.txt").string()), "# my own cameras\n");
  std::ifstream in(workdir_ / "summary.json");
  EXPECT_EQ(json::parse(in)["status"], "failed");
}

// A failed run moves raytime's exports aside (so that no earlier run's poses stay under the
// names users train from); the user's files stay where they were.
TEST_F(UsersFilesTest, AFailedRunMovesOnlyRaytimesFilesAside) {
  ASSERT_EQ(Demo().exit_code, 0);
  AddUsersFiles();
  EXPECT_EQ(Demo("--set prior.convention=inverted").exit_code, 2);
  ExpectUsersFilesKept();
  EXPECT_FALSE(fs::exists(workdir_ / "refined" / "images.txt"));
  EXPECT_TRUE(fs::exists(workdir_ / "stale" / "refined" / "images.txt"));
  EXPECT_FALSE(fs::exists(workdir_ / "stale" / "refined" / "notes.txt"));
  // And the next good run writes beside them again.
  const CommandResult good = Demo();
  ASSERT_EQ(good.exit_code, 0) << good.output;
  ExpectUsersFilesKept();
  EXPECT_TRUE(fs::exists(workdir_ / "refined" / "images.txt"));
}

// An image named with escape sequences retitled the terminal and recoloured the log.
TEST_F(UsersFilesTest, AnImageNamesEscapeSequencesAreShownNotObeyed) {
  const fs::path scene = CopySampleScene(dir_ / "scene");
  const std::string name = "\x1b]0;owned\x07\x1b[31m0003.jpg";
  fs::rename(scene / "images" / "0003.jpg", scene / "images" / name);
  fs::rename(scene / "gt_dense_cameras" / "0003.jpg.camera",
             scene / "gt_dense_cameras" / (name + ".camera"));
  const CommandResult run = RunRaytime("run configs/demo.yaml --workdir " + workdir_.string() +
                                       " --set dataset.root=" + scene.string());
  EXPECT_EQ(run.output.find('\x1b'), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find('\x07'), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("\\x1B]0;owned\\x07\\x1B[31m0003.jpg"), std::string::npos)
      << run.output;
}

}  // namespace
}  // namespace raytime
