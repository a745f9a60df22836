// What raytime wrote in a folder (core/written_files.h, issue 47): its record, what is the user's,
// collisions and the carry into a replacement, and WriteDirectoryAtomically keeping the rest.
#include "core/written_files.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "core/error.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

void Write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

class WrittenFilesTest : public TempDirTest {
 protected:
  WrittenFilesTest() : TempDirTest("written") {}

  // A folder as an export writes it: two files and one in a subfolder.
  fs::path Export() {
    const fs::path folder = dir_ / "refined";
    WriteDirectoryAtomically(folder.string(), [](const std::string& tmp) {
      Write(fs::path(tmp) / "images.txt", "raytime's images");
      Write(fs::path(tmp) / "cameras.txt", "raytime's cameras");
      Write(fs::path(tmp) / "sparse" / "0" / "points3D.txt", "raytime's points");
    });
    return folder;
  }
};

// A copy of the folder (cp -r gives every file a new time) is still raytime's; an edit of the same
// length is still the user's. The record held sizes and times alone, and a rerun in a copied work
// directory refused to replace raytime's own cameras.txt ("was not written by raytime").
TEST_F(WrittenFilesTest, ACopyIsStillRaytimesAnEditOfTheSameLengthIsNot) {
  const fs::path folder = Export();
  const fs::path copy = dir_ / "copy";
  fs::copy(folder, copy, fs::copy_options::recursive);
  fs::last_write_time(copy / "images.txt",
                      fs::last_write_time(copy / "images.txt") + std::chrono::seconds(5));
  EXPECT_TRUE(FilesNotWritten(copy.string()).empty());
  Write(copy / "images.txt", "raytime's imageS");
  EXPECT_EQ(FilesNotWritten(copy.string()), (std::vector<std::string>{"images.txt"}));
}

TEST_F(WrittenFilesTest, TheUsersEntriesAreThoseNotRecordedOrChanged) {
  const fs::path folder = Export();
  EXPECT_TRUE(fs::exists(folder / kWrittenFilesRecord));
  EXPECT_TRUE(FilesNotWritten(folder.string()).empty());
  Write(folder / "notes.txt", "mine");
  Write(folder / "state" / "a" / "step.ckpt", "mine");
  Write(folder / "sparse" / "0" / "extra.txt", "mine");
  fs::create_directories(folder / "empty");
  // A file raytime wrote and someone changed since is theirs now.
  Write(folder / "cameras.txt", "my cameras, longer than raytime's");
  EXPECT_EQ(FilesNotWritten(folder.string()),
            (std::vector<std::string>{"cameras.txt", "empty", "notes.txt", "sparse/0/extra.txt",
                                      "state"}));
  // Without a record nothing is raytime's.
  fs::remove(folder / kWrittenFilesRecord);
  EXPECT_EQ(FilesNotWritten(folder.string()).size(), 6u);
}

TEST_F(WrittenFilesTest, AReplacementKeepsTheUsersFilesAndRefusesOneUnderItsNames) {
  const fs::path folder = Export();
  Write(folder / "notes.txt", "mine");
  Write(folder / "sparse" / "mine" / "model.txt", "mine");
  const fs::path again = Export();
  EXPECT_EQ(ReadTextFile((again / "notes.txt").string()), "mine");
  EXPECT_EQ(ReadTextFile((again / "sparse" / "mine" / "model.txt").string()), "mine");
  EXPECT_EQ(ReadTextFile((again / "images.txt").string()), "raytime's images");
  // Still the user's after the replacement (the record lists raytime's files only).
  EXPECT_EQ(FilesNotWritten(again.string()),
            (std::vector<std::string>{"notes.txt", "sparse/mine"}));

  Write(folder / "images.txt", "my images, not raytime's");
  try {
    Export();
    FAIL() << "a file of the user's under a name raytime writes was replaced";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find((folder / "images.txt").string() +
                                         " was not written by raytime"),
              std::string::npos)
        << e.what();
  }
  EXPECT_EQ(ReadTextFile((folder / "images.txt").string()), "my images, not raytime's");
  EXPECT_EQ(ReadTextFile((folder / "notes.txt").string()), "mine");
  // No temporary left beside it.
  for (const auto& entry : fs::directory_iterator(dir_)) {
    EXPECT_EQ(entry.path().filename(), "refined");
  }
}

TEST_F(WrittenFilesTest, CollisionsAreSamePathsOrPathsThroughAFileAndFoldersMerge) {
  Write(dir_ / "from" / "a.txt", "x");
  Write(dir_ / "from" / "d" / "inner.txt", "x");
  Write(dir_ / "from" / "f" / "g.txt", "x");
  Write(dir_ / "from" / "m" / "own.txt", "x");
  Write(dir_ / "to" / "a.txt", "y");
  Write(dir_ / "to" / "d" / "inner.txt", "y");
  Write(dir_ / "to" / "f", "a file where theirs is a folder");
  Write(dir_ / "to" / "m" / "raytime.txt", "y");
  const std::vector<std::string> entries = {"a.txt", "d", "f/g.txt", "m"};
  EXPECT_EQ(CollidingEntries(entries, (dir_ / "from").string(), (dir_ / "to").string()),
            (std::vector<std::string>{"a.txt", "d/inner.txt", "f/g.txt"}));
  CarryEntriesOver({"m"}, (dir_ / "from").string(), (dir_ / "to").string());
  EXPECT_TRUE(fs::exists(dir_ / "to" / "m" / "own.txt"));
  EXPECT_TRUE(fs::exists(dir_ / "to" / "m" / "raytime.txt"));
}

// A folder an earlier raytime wrote, which kept no record: kept whole beside the new one, whose
// names it shares; what it holds under other names is carried into the new one.
TEST_F(WrittenFilesTest, AFolderWithoutARecordIsKeptBesideTheNewOne) {
  Write(dir_ / "refined" / "cameras.txt", "an earlier raytime's cameras");
  Write(dir_ / "refined" / "notes.txt", "mine");
  const fs::path folder = Export();
  EXPECT_EQ(ReadTextFile((folder / "cameras.txt").string()), "raytime's cameras");
  EXPECT_EQ(ReadTextFile((folder / "notes.txt").string()), "mine");
  EXPECT_EQ(ReadTextFile((dir_ / "refined.before-record" / "cameras.txt").string()),
            "an earlier raytime's cameras");
  EXPECT_EQ(FilesNotWritten(folder.string()), std::vector<std::string>{"notes.txt"});
}

// Where something is kept aside, what an earlier keep left there is not replaced.
TEST_F(WrittenFilesTest, AnUnusedPathNeverNamesWhatIsThere) {
  const std::string wanted = (dir_ / "kept").string();
  EXPECT_EQ(UnusedPath(wanted), wanted);
  Write(wanted, "first");
  Write(wanted + ".1", "second");
  EXPECT_EQ(UnusedPath(wanted), wanted + ".2");
}

TEST_F(WrittenFilesTest, AFileWhereRaytimeWritesAFolderIsNotReplaced) {
  Write(dir_ / "refined", "a file of the user's");
  EXPECT_THROW(Export(), InputError);
  EXPECT_EQ(ReadTextFile((dir_ / "refined").string()), "a file of the user's");
}

}  // namespace
}  // namespace raytime
