// Interoperability with the real COLMAP 3.8 binary: models raytime writes (text and binary) go
// through `colmap model_converter` and must read back with poses unchanged to 1e-9 and
// intrinsics, keypoints and tracks bit-identical. This pins down the binary layout, the camera
// model ids and the text syntax against COLMAP itself rather than against our own reader.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "formats/colmap_model.h"
#include "testing/random_draws.h"
#include "tests/colmap_command.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr double kPoseTolerance = 1e-9;

// Converts the model in `input` to `output_type` (TXT or BIN) in `output` with the real COLMAP.
// Fails the test with COLMAP's output when it cannot run.
void ColmapConvert(const std::string& input, const std::string& output,
                   const std::string& output_type) {
  const std::string colmap = FindOnPath("colmap");
  ASSERT_FALSE(colmap.empty())
      << "the COLMAP 3.8 binary `colmap` is not on PATH; this test needs it (CI installs it)";
  fs::create_directories(output);
  const std::string log = output + ".log";
  const std::vector<std::string> args = {"model_converter", "--input_path", input,
                                         "--output_path",   output,         "--output_type",
                                         output_type};
  const ProcessStatus status = RunColmap(colmap, args, log);
  ASSERT_TRUE(status.Succeeded()) << CommandLine(args) << " " << status.Describe() << "\n"
                                  << ReadTextFile(log);
}

// A raytime scene: two cameras (one with OpenCV distortion), random rotations and centres.
// Principal points lie in [520, 1000) so the +0.5 COLMAP shift is exact in both directions.
void MakeScene(ImageSet* images, PoseSet* poses) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> principal(520.0, 1000.0), centre(-20.0, 20.0);
  for (int c = 0; c < 2; ++c) {
    CameraIntrinsics k;
    k.width = 1536;
    k.height = 1024 + 8 * c;
    k.params = {1379.7412345678 + c, 1382.0812345678, principal(rng), principal(rng), 0, 0, 0, 0};
    if (c == 1) k.params = {1500.123, 1499.987, 767.25, 511.75, -0.12345, 0.0345, 1e-4, -2e-5};
    images->cameras.push_back(k);
  }
  for (int i = 0; i < 9; ++i) {
    const std::string name = "img_" + std::to_string(i) + ".jpg";
    images->images.push_back({name, 1536, images->cameras[i % 2].height, i % 2});
    const Eigen::Quaterniond q = DrawQuaternion([&] { return normal(rng); });
    poses->world_from_cam[name] = Rigid3(q.normalized(), DrawVector3([&] { return centre(rng); }));
  }
}

// Every COLMAP 3.8 camera model (so a wrong model id shows up as a wrong name after COLMAP
// rewrites the model as text), keypoints with and without 3D points, and consistent tracks.
ColmapModel MakeRawModel() {
  ImageSet images;
  PoseSet poses;
  MakeScene(&images, &poses);
  ColmapModel model = ToColmapModel(images, poses);
  const std::vector<std::pair<std::string, size_t>> camera_models = {{"SIMPLE_PINHOLE", 3},
                                                                     {"PINHOLE", 4},
                                                                     {"SIMPLE_RADIAL", 4},
                                                                     {"RADIAL", 5},
                                                                     {"OPENCV", 8},
                                                                     {"OPENCV_FISHEYE", 8},
                                                                     {"FULL_OPENCV", 12},
                                                                     {"FOV", 5},
                                                                     {"SIMPLE_RADIAL_FISHEYE", 4},
                                                                     {"RADIAL_FISHEYE", 5},
                                                                     {"THIN_PRISM_FISHEYE", 12}};
  for (size_t m = 0; m < camera_models.size(); ++m) {
    ColmapCamera camera{uint32_t(10 + m), camera_models[m].first, 640 + m, 480, {}};
    for (size_t p = 0; p < camera_models[m].second; ++p) {
      camera.params.push_back(p < 3 ? 300.0 + 1.0 / (p + 3) : 1e-3 / (p + 1));
    }
    model.cameras[camera.camera_id] = camera;
  }
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> pixel(0.0, 1000.0);
  uint64_t next_point_id = 1;
  for (auto& [image_id, image] : model.images) {
    for (uint32_t k = 0; k < 5; ++k) {
      image.points2D.push_back(DrawVector2([&] { return pixel(rng); }));
      if (k % 2 == 0) {
        image.point3D_ids.push_back(kInvalidPoint3DId);
        continue;
      }
      ColmapPoint3D point;
      point.point3D_id = next_point_id++;
      const double z = pixel(rng) / 3;
      const double y = -pixel(rng);
      point.xyz = Eigen::Vector3d(pixel(rng), y, z);
      point.rgb[0] = uint8_t(k * 50);
      point.rgb[1] = 255;
      point.error = pixel(rng) / 1000;
      point.track.push_back({image_id, k});
      image.point3D_ids.push_back(point.point3D_id);
      model.points3D[point.point3D_id] = point;
    }
  }
  return model;
}

void ExpectModelsEqual(const ColmapModel& expected, const ColmapModel& actual) {
  ASSERT_EQ(actual.cameras.size(), expected.cameras.size());
  for (const auto& [id, camera] : expected.cameras) {
    ASSERT_TRUE(actual.cameras.count(id)) << "camera " << id;
    const ColmapCamera& other = actual.cameras.at(id);
    EXPECT_EQ(other.model, camera.model) << "camera " << id;
    EXPECT_EQ(other.width, camera.width) << "camera " << id;
    EXPECT_EQ(other.height, camera.height) << "camera " << id;
    EXPECT_EQ(other.params, camera.params) << "camera " << id;
  }
  ASSERT_EQ(actual.images.size(), expected.images.size());
  for (const auto& [id, image] : expected.images) {
    ASSERT_TRUE(actual.images.count(id)) << "image " << id;
    const ColmapImage& other = actual.images.at(id);
    EXPECT_EQ(other.name, image.name);
    EXPECT_EQ(other.camera_id, image.camera_id) << image.name;
    EXPECT_LT(RotationDistance(other.cam_from_world.rotation, image.cam_from_world.rotation),
              kPoseTolerance)
        << image.name;
    EXPECT_LT(
        (other.cam_from_world.Inverse().translation - image.cam_from_world.Inverse().translation)
            .norm(),
        kPoseTolerance)
        << image.name;
    EXPECT_EQ(other.points2D, image.points2D) << image.name;
    EXPECT_EQ(other.point3D_ids, image.point3D_ids) << image.name;
  }
  ASSERT_EQ(actual.points3D.size(), expected.points3D.size());
  for (const auto& [id, point] : expected.points3D) {
    ASSERT_TRUE(actual.points3D.count(id)) << "point " << id;
    const ColmapPoint3D& other = actual.points3D.at(id);
    EXPECT_EQ(other.xyz, point.xyz) << "point " << id;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(other.rgb[c], point.rgb[c]) << "point " << id;
    EXPECT_EQ(other.error, point.error) << "point " << id;
    ASSERT_EQ(other.track.size(), point.track.size()) << "point " << id;
    for (size_t t = 0; t < point.track.size(); ++t) {
      EXPECT_EQ(other.track[t].image_id, point.track[t].image_id);
      EXPECT_EQ(other.track[t].point2D_idx, point.track[t].point2D_idx);
    }
  }
}

TEST(ColmapInterop, RaytimeModelSurvivesColmapConversion) {
  ImageSet images;
  PoseSet poses;
  MakeScene(&images, &poses);
  TempDir tmp("colmap");
  WriteColmapModelBinary(ToColmapModel(images, poses), tmp / "ours_bin");
  WriteColmapModelText(ToColmapModel(images, poses), tmp / "ours_txt");
  ASSERT_NO_FATAL_FAILURE(ColmapConvert(tmp / "ours_bin", tmp / "colmap_txt", "TXT"));
  ASSERT_NO_FATAL_FAILURE(ColmapConvert(tmp / "ours_txt", tmp / "colmap_bin", "BIN"));
  for (const char* converted : {"colmap_txt", "colmap_bin"}) {
    SCOPED_TRACE(converted);
    ImageSet images_read;
    PoseSet poses_read;
    FromColmapModel(ReadColmapModel(tmp / converted), &images_read, &poses_read);
    EXPECT_EQ(images_read.cameras, images.cameras);
    ASSERT_EQ(Names(images_read), Names(images));
    for (size_t i = 0; i < images.images.size(); ++i) {
      EXPECT_EQ(images_read.images[i].camera_index, images.images[i].camera_index);
    }
    ASSERT_EQ(Names(poses_read), Names(poses));
    for (const auto& [name, pose] : poses.world_from_cam) {
      const Rigid3& read = poses_read.world_from_cam.at(name);
      EXPECT_LT(RotationDistance(read.rotation, pose.rotation), kPoseTolerance) << name;
      EXPECT_LT((read.translation - pose.translation).norm(), kPoseTolerance) << name;
    }
  }
}

TEST(ColmapInterop, EveryCameraModelKeypointAndTrackSurvives) {
  const ColmapModel model = MakeRawModel();
  TempDir tmp("colmap");
  WriteColmapModelBinary(model, tmp / "ours_bin");
  WriteColmapModelText(model, tmp / "ours_txt");
  ASSERT_NO_FATAL_FAILURE(ColmapConvert(tmp / "ours_bin", tmp / "colmap_txt", "TXT"));
  ASSERT_NO_FATAL_FAILURE(ColmapConvert(tmp / "ours_txt", tmp / "colmap_bin", "BIN"));
  {
    SCOPED_TRACE("binary -> COLMAP -> text");
    ExpectModelsEqual(model, ReadColmapModelText(tmp / "colmap_txt"));
  }
  {
    SCOPED_TRACE("text -> COLMAP -> binary");
    ExpectModelsEqual(model, ReadColmapModelBinary(tmp / "colmap_bin"));
  }
}

}  // namespace
}  // namespace raytime
