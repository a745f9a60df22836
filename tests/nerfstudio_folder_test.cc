// A nerfstudio folder's transforms.json written back into a work directory (issue 49,
// formats/nerfstudio_folder.h): every key kept in its order, only the poses (and changed
// intrinsics) replaced, frames without a new pose moved out of frames and the split lists, and
// every path resolving from the work directory to the folder's files.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "formats/nerfstudio.h"
#include "formats/nerfstudio_folder.h"
#include "input_error_of.h"
#include "temp_dir.h"

namespace raytime {
namespace {

namespace fs = std::filesystem;
using nlohmann::ordered_json;

void WriteFixtureFile(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

ordered_json InputMatrix(double x) {
  return {{1.0, 0.0, 0.0, x}, {0.0, 1.0, 0.0, 0.0}, {0.0, 0.0, 1.0, 0.0}, {0.0, 0.0, 0.0, 1.0}};
}

// The transform_matrix of an identity rotation in OpenCV's axes at (x, 0, 0): OpenGL's y and z
// point the other way.
ordered_json GlMatrix(double x) {
  return {{1.0, 0.0, 0.0, x}, {0.0, -1.0, 0.0, 0.0}, {0.0, 0.0, -1.0, 0.0}, {0.0, 0.0, 0.0, 1.0}};
}

// A folder as ns-process-data writes one: shared intrinsics, three frames with depth and mask
// paths, a split, a point cloud, a downscaled image folder and keys of the user's own.
struct NerfstudioFixture {
  TempDir dir{"nerfstudio_folder"};
  fs::path input = dir.path() / "capture";
  fs::path output = dir.path() / "work";
  std::string text;

  NerfstudioFixture() {
    ordered_json frames = ordered_json::array();
    for (int i = 0; i < 3; ++i) {
      const std::string n = std::to_string(i);
      frames.push_back({{"file_path", "images/f" + n + ".jpg"},
                        {"transform_matrix", InputMatrix(i)},
                        {"colmap_im_id", i + 1},
                        {"depth_file_path", "depths/f" + n + ".png"},
                        {"mask_path", "./masks/f" + n + ".png"},
                        {"mine", {{"nested", i}}}});
      for (const char* folder : {"images", "images_2", "depths", "masks"}) {
        const std::string extension = std::string(folder).rfind("images", 0) == 0 ? ".jpg" : ".png";
        WriteFixtureFile(input / folder / ("f" + n + extension), folder + n);
      }
    }
    const ordered_json document = {{"w", 640},
                                   {"h", 480},
                                   {"fl_x", 500.0},
                                   {"fl_y", 500.0},
                                   {"cx", 320.0},
                                   {"cy", 240.0},
                                   {"camera_model", "OPENCV"},
                                   {"frames", frames},
                                   {"applied_transform", ordered_json::array({{0, 1, 0, 0}})},
                                   {"ply_file_path", "sparse_pc.ply"},
                                   {"train_filenames", {"images/f0.jpg", "images/f1.jpg"}},
                                   {"test_filenames", {"images/f2.jpg"}},
                                   {"zz_user_key", "kept"}};
    text = document.dump(2);
    WriteFixtureFile(input / "transforms.json", text);
    WriteFixtureFile(input / "sparse_pc.ply", "ply");
  }

  // Frames 0 and 2 refined, moved along x by 10; frame 1 left out.
  NerfstudioUpdate Update() const {
    NerfstudioUpdate update;
    for (const int i : {0, 2}) {
      update.poses.world_from_cam["f" + std::to_string(i) + ".jpg"] =
          Rigid3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(10 + i, 0, 0));
    }
    update.frame_fields["f1.jpg"] = {{"raytime_verdict", "doubted"}};
    update.frame_fields["f2.jpg"] = {{"raytime_verdict", "held"}};
    return update;
  }

  NerfstudioWriteSummary Write(const NerfstudioUpdate& update) const {
    return WriteNerfstudioFolder((input / "transforms.json").string(), text, output.string(),
                                 update, {"summary.json"});
  }
};

std::vector<std::string> KeysOf(const ordered_json& object) {
  std::vector<std::string> keys;
  for (const auto& item : object.items()) keys.push_back(item.key());
  return keys;
}

TEST(NerfstudioFolder, KeepsEveryKeyAndChangesOnlyThePoses) {
  const NerfstudioFixture folder;
  const NerfstudioWriteSummary summary = folder.Write(folder.Update());
  EXPECT_EQ(summary.frames_updated, 2);
  EXPECT_EQ(summary.left_out, std::vector<std::string>{"f1.jpg"});
  EXPECT_FALSE(summary.intrinsics_updated);
  const ordered_json before = ordered_json::parse(folder.text);
  const ordered_json after = ordered_json::parse(ReadTextFile(summary.path));

  std::vector<std::string> keys = KeysOf(before);
  keys.push_back("raytime_left_out_frames");
  EXPECT_EQ(KeysOf(after), keys);  // the input's order, ours appended
  for (const auto& [key, value] : before.items()) {
    if (key == "frames" || key == "train_filenames") continue;
    EXPECT_EQ(after[key], value) << key;
  }
  // Frame 1 is no trainer's any more: out of frames and the split, whole in the left-out list.
  EXPECT_EQ(after["train_filenames"], ordered_json({"images/f0.jpg"}));
  ASSERT_EQ(after["frames"].size(), 2u);
  ASSERT_EQ(after["raytime_left_out_frames"].size(), 1u);
  ordered_json left_out = after["raytime_left_out_frames"][0];
  EXPECT_EQ(left_out["raytime_verdict"], "doubted");
  left_out.erase("raytime_verdict");
  EXPECT_EQ(left_out, before["frames"][1]);

  for (const int k : {0, 1}) {
    const int i = k == 0 ? 0 : 2;
    ordered_json frame = after["frames"][k];
    EXPECT_EQ(frame["transform_matrix"], GlMatrix(10 + i));
    EXPECT_EQ(frame["raytime_verdict"], i == 2 ? ordered_json("held") : ordered_json());
    frame.erase("transform_matrix");
    frame.erase("raytime_verdict");
    ordered_json original = before["frames"][i];
    original.erase("transform_matrix");
    EXPECT_EQ(frame, original);
  }
}

TEST(NerfstudioFolder, EveryPathResolvesFromTheWorkDirectoryToTheSameFile) {
  const NerfstudioFixture folder;
  const NerfstudioWriteSummary summary = folder.Write(folder.Update());
  EXPECT_EQ(summary.links,
            (std::vector<std::string>{"depths", "images", "images_2", "masks", "sparse_pc.ply"}));
  const ordered_json after = ordered_json::parse(ReadTextFile(summary.path));
  std::vector<std::string> paths = {after["ply_file_path"]};
  for (const char* frames : {"frames", "raytime_left_out_frames"}) {
    for (const auto& frame : after[frames]) {
      for (const char* key : {"file_path", "depth_file_path", "mask_path"}) {
        paths.push_back(frame[key]);
      }
    }
  }
  ASSERT_EQ(paths.size(), 10u);
  for (const std::string& path : paths) {
    EXPECT_TRUE(fs::equivalent(folder.output / path, folder.input / path)) << path;
  }
  // nerfstudio's downscaled sibling, found from the work directory as from the folder.
  EXPECT_TRUE(fs::equivalent(folder.output / "images_2/f0.jpg", folder.input / "images_2/f0.jpg"));
  // Written again (a rerun): the links are reused, the result is the same.
  const std::string first = ReadTextFile(summary.path);
  folder.Write(folder.Update());
  EXPECT_EQ(ReadTextFile(summary.path), first);
}

TEST(NerfstudioFolder, APathTheWorkDirectoryCannotLinkIsWrittenAbsolute) {
  const NerfstudioFixture folder;
  fs::create_directories(folder.output / "masks");  // something else of that name is there
  const NerfstudioWriteSummary summary = folder.Write(folder.Update());
  EXPECT_EQ(summary.absolute, std::vector<std::string>{"masks"});
  const ordered_json after = ordered_json::parse(ReadTextFile(summary.path));
  const std::string mask = after["frames"][0]["mask_path"];
  EXPECT_EQ(mask, (fs::absolute(folder.input) / "masks/f0.png").lexically_normal().string());
  EXPECT_TRUE(fs::exists(mask));
  EXPECT_EQ(after["frames"][0]["file_path"], "images/f0.jpg");
}

TEST(NerfstudioFolder, SelfCalibratedIntrinsicsGoWhereNerfstudioReadsThem) {
  const NerfstudioFixture folder;
  NerfstudioUpdate update = folder.Update();
  const TransformsFrames read = ReadTransformsFrames(
      "t", ParseTransformsJson("t", ReadTextFile((folder.input / "transforms.json").string())));
  CameraIntrinsics camera = read.frames[0].camera;
  camera.params[kFx] = 510;  // shared by every frame: stays at the top level
  update.cameras = {{"f0.jpg", camera}, {"f2.jpg", camera}};
  ordered_json after = ordered_json::parse(ReadTextFile(folder.Write(update).path));
  EXPECT_EQ(after["fl_x"], 510.0);
  EXPECT_FALSE(after["frames"][0].contains("fl_x"));

  CameraIntrinsics other = camera;
  other.params[kFx] = 520;
  other.params[kK1] = 0.01;
  update.cameras["f2.jpg"] = other;  // now the frames differ: each states its own, top removed
  after = ordered_json::parse(ReadTextFile(folder.Write(update).path));
  EXPECT_FALSE(after.contains("fl_x"));
  EXPECT_EQ(after["fl_y"], 500.0);
  EXPECT_EQ(after["frames"][0]["fl_x"], 510.0);
  EXPECT_EQ(after["frames"][1]["fl_x"], 520.0);
  EXPECT_EQ(after["frames"][1]["k1"], 0.01);
  EXPECT_FALSE(after["frames"][0].contains("k1"));
  // Read back as nerfstudio reads it, each frame has its own camera.
  const std::string path = (folder.output / "transforms.json").string();
  const TransformsFrames back =
      ReadTransformsFrames(path, ParseTransformsJson(path, ReadTextFile(path)));
  EXPECT_EQ(back.frames[0].camera.params[kFx], 510);
  EXPECT_EQ(back.frames[1].camera.params[kFx], 520);
  EXPECT_EQ(back.frames[1].camera.params[kK1], 0.01);
}

TEST(NerfstudioFolder, NeverWritesOverTheInput) {
  const NerfstudioFixture folder;
  const std::string message = InputErrorOf([&] {
    WriteNerfstudioFolder((folder.input / "transforms.json").string(), folder.text,
                          folder.input.string(), folder.Update(), {});
  });
  EXPECT_NE(message.find("choose another --workdir"), std::string::npos) << message;
  EXPECT_EQ(ReadTextFile((folder.input / "transforms.json").string()), folder.text);
}

}  // namespace
}  // namespace raytime
