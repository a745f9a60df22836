// Round trips and error reporting of the file formats (formats): COLMAP text and binary,
// nerfstudio transforms.json, TUM trajectories and Strecha cameras. Poses must survive every
// conversion to 1e-9 and intrinsics exactly (SPEC §2, §7), and bad input must name the file,
// the line or frame, and what was expected.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/terminal_text.h"
#include "core/warnings.h"
#include "formats/colmap_model.h"
#include "formats/dataset.h"
#include "formats/nerfstudio.h"
#include "formats/strecha.h"
#include "formats/tum.h"
#include "testing/random_draws.h"
#include "tests/input_error_of.h"
#include "tests/shared_data.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr double kPoseTolerance = 1e-9;

void WriteFile(const std::string& path, const std::string& contents) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << contents;
}

// A principal point survives the +0.5 / -0.5 of the COLMAP and nerfstudio conventions exactly
// when c + 0.5 stays in c's binade, so the test draws it from [520, 1000).
double ExactlyShiftable(std::mt19937_64& rng) {
  const double c = std::uniform_real_distribution<double>(520.0, 1000.0)(rng);
  EXPECT_EQ((c + 0.5) - 0.5, c);
  return c;
}

struct DatasetScene {
  ImageSet images;
  PoseSet poses;
};

// Random rotations (uniform on SO(3) via normalized Gaussian quaternions) and centres; three
// cameras, one with OpenCV distortion.
DatasetScene MakeDatasetScene(int num_images, int num_cameras, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(-10.0, 10.0);
  DatasetScene scene;
  for (int c = 0; c < num_cameras; ++c) {
    CameraIntrinsics k;
    k.width = 1536 + 64 * c;
    k.height = 1024 + 32 * c;
    k.params = {1379.7412345678 + 10 * c,
                1382.0812345678 - 7 * c,
                ExactlyShiftable(rng),
                ExactlyShiftable(rng),
                0,
                0,
                0,
                0};
    if (c == 1) {
      k.params[kK1] = -0.1234567890123;
      k.params[kK2] = 0.0456789012345;
      k.params[kP1] = 1.2345e-4;
      k.params[kP2] = -6.789e-5;
    }
    scene.images.cameras.push_back(k);
  }
  for (int i = 0; i < num_images; ++i) {
    char name[32];
    snprintf(name, sizeof(name), "frame_%04d.jpg", i);
    const int camera = i % num_cameras;
    scene.images.images.push_back(
        {name, scene.images.cameras[camera].width, scene.images.cameras[camera].height, camera});
    const Eigen::Quaterniond q = DrawQuaternion([&] { return normal(rng); });
    scene.poses.world_from_cam[name] =
        Rigid3(q.normalized(), DrawVector3([&] { return uniform(rng); }));
  }
  return scene;
}

void ExpectPosesEqual(const PoseSet& expected, const PoseSet& actual) {
  ASSERT_EQ(Names(expected), Names(actual));
  for (const auto& [name, pose] : expected.world_from_cam) {
    const Rigid3& other = actual.world_from_cam.at(name);
    EXPECT_LT(RotationDistance(pose.rotation, other.rotation), kPoseTolerance) << name;
    EXPECT_LT((pose.translation - other.translation).norm(), kPoseTolerance) << name;
  }
}

// Camera indices may be renumbered by a format; each image's intrinsics must match exactly.
void ExpectImagesEqual(const ImageSet& expected, const ImageSet& actual) {
  ASSERT_EQ(Names(expected), Names(actual));
  for (size_t i = 0; i < expected.images.size(); ++i) {
    const ImageInfo& a = expected.images[i];
    const ImageInfo& b = actual.images[i];
    EXPECT_EQ(a.width, b.width) << a.name;
    EXPECT_EQ(a.height, b.height) << a.name;
    const CameraIntrinsics& ka = expected.cameras.at(a.camera_index);
    const CameraIntrinsics& kb = actual.cameras.at(b.camera_index);
    EXPECT_EQ(ka.width, kb.width) << a.name;
    EXPECT_EQ(ka.height, kb.height) << a.name;
    for (int p = 0; p < kNumIntrinsics; ++p) EXPECT_EQ(ka.params[p], kb.params[p]) << a.name;
  }
}

TEST(Formats, ColmapTextBinaryAndTransformsJsonRoundTrip) {
  const DatasetScene scene = MakeDatasetScene(12, 3, 1);
  TempDir tmp("formats");

  WriteColmapModelText(ToColmapModel(scene.images, scene.poses), tmp / "text");
  ImageSet images_text;
  PoseSet poses_text;
  FromColmapModel(ReadColmapModel(tmp / "text"), &images_text, &poses_text);
  ExpectImagesEqual(scene.images, images_text);
  ExpectPosesEqual(scene.poses, poses_text);
  EXPECT_EQ(images_text.cameras, scene.images.cameras);  // one COLMAP camera per camera, in order

  WriteColmapModelBinary(ToColmapModel(images_text, poses_text), tmp / "bin");
  ImageSet images_bin;
  PoseSet poses_bin;
  FromColmapModel(ReadColmapModel(tmp / "bin"), &images_bin, &poses_bin);
  ExpectImagesEqual(scene.images, images_bin);
  ExpectPosesEqual(scene.poses, poses_bin);

  WriteTransformsJson(tmp / "ns/transforms.json", images_bin, poses_bin);
  ImageSet images_json;
  PoseSet poses_json;
  ReadTransformsJson(tmp / "ns/transforms.json", &images_json, &poses_json);
  ExpectImagesEqual(scene.images, images_json);
  ExpectPosesEqual(scene.poses, poses_json);
  EXPECT_EQ(images_json.image_root, tmp / "ns/images");
  EXPECT_TRUE(TemporaryFilesBelow(tmp.path()).empty());
}

TEST(Formats, ColmapCameraConventions) {
  const DatasetScene scene = MakeDatasetScene(2, 2, 2);
  const ColmapModel model = ToColmapModel(scene.images, scene.poses);
  const ColmapCamera& pinhole = model.cameras.at(1);
  const ColmapCamera& opencv = model.cameras.at(2);
  EXPECT_EQ(pinhole.model, "PINHOLE");
  ASSERT_EQ(pinhole.params.size(), 4u);
  EXPECT_EQ(pinhole.params[2], scene.images.cameras[0].cx() + 0.5);
  EXPECT_EQ(pinhole.params[3], scene.images.cameras[0].cy() + 0.5);
  EXPECT_EQ(opencv.model, "OPENCV");
  EXPECT_EQ(opencv.params.size(), 8u);
  // COLMAP stores world-to-camera: the camera centre is -R^T t.
  const ColmapImage& image = model.images.at(1);
  EXPECT_EQ(image.name, "frame_0000.jpg");
  EXPECT_LT((image.cam_from_world.Inverse().translation -
             scene.poses.world_from_cam.at("frame_0000.jpg").translation)
                .norm(),
            1e-12);

  ColmapCamera simple_radial{7, "SIMPLE_RADIAL", 640, 480, {500.0, 320.5, 240.5, -0.01}};
  const CameraIntrinsics k = IntrinsicsFromColmap(simple_radial);
  EXPECT_EQ(k.params, (std::array<double, 8>{500, 500, 320, 240, -0.01, 0, 0, 0}));
  ColmapCamera fisheye{3, "OPENCV_FISHEYE", 640, 480, std::vector<double>(8, 1.0)};
  const std::string message = InputErrorOf([&] { IntrinsicsFromColmap(fisheye); });
  EXPECT_NE(message.find("OPENCV_FISHEYE"), std::string::npos) << message;
}

// Keypoints, tracks and every COLMAP camera model survive both encodings unchanged.
TEST(Formats, ColmapRawModelRoundTrip) {
  ColmapModel model;
  const std::vector<std::pair<std::string, size_t>> models = {
      {"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4},      {"SIMPLE_RADIAL", 4},      {"RADIAL", 5},
      {"OPENCV", 8},         {"FULL_OPENCV", 12}, {"THIN_PRISM_FISHEYE", 12}};
  for (size_t c = 0; c < models.size(); ++c) {
    ColmapCamera camera{uint32_t(c + 1), models[c].first, 800, 600, {}};
    for (size_t p = 0; p < models[c].second; ++p) camera.params.push_back(0.1 * p + 1.0 / 3.0);
    model.cameras[camera.camera_id] = camera;
  }
  ColmapImage image;
  image.image_id = 5;
  image.name = "sub/dir/a.png";
  image.camera_id = 3;
  image.cam_from_world = Rigid3(Eigen::Quaterniond(0.5, -0.5, 0.5, 0.5), {1.0 / 7, 2, -3});
  image.points2D = {{10.25, 20.5}, {1.0 / 3, 2.0 / 3}};
  image.point3D_ids = {kInvalidPoint3DId, 42};
  model.images[5] = image;
  ColmapPoint3D point;
  point.point3D_id = 42;
  point.xyz = {0.1, -0.2, 1e-20};
  point.rgb[0] = 255;
  point.rgb[2] = 7;
  point.error = 0.123456789;
  point.track = {{5, 1}};
  model.points3D[42] = point;

  TempDir tmp("formats");
  WriteColmapModelText(model, tmp / "text");
  WriteColmapModelBinary(model, tmp / "bin");
  for (const ColmapModel& read :
       {ReadColmapModelText(tmp / "text"), ReadColmapModelBinary(tmp / "bin")}) {
    ASSERT_EQ(read.cameras.size(), model.cameras.size());
    for (const auto& [id, camera] : model.cameras) {
      EXPECT_EQ(read.cameras.at(id).model, camera.model);
      EXPECT_EQ(read.cameras.at(id).width, camera.width);
      EXPECT_EQ(read.cameras.at(id).params, camera.params);
    }
    const ColmapImage& got = read.images.at(5);
    EXPECT_EQ(got.name, image.name);
    EXPECT_EQ(got.camera_id, 3u);
    EXPECT_LT(RotationDistance(got.cam_from_world.rotation, image.cam_from_world.rotation), 1e-15);
    EXPECT_EQ(got.cam_from_world.translation, image.cam_from_world.translation);
    EXPECT_EQ(got.points2D, image.points2D);
    EXPECT_EQ(got.point3D_ids, image.point3D_ids);
    const ColmapPoint3D& p = read.points3D.at(42);
    EXPECT_EQ(p.xyz, point.xyz);
    EXPECT_EQ(p.rgb[0], 255);
    EXPECT_EQ(p.rgb[2], 7);
    EXPECT_EQ(p.error, point.error);
    ASSERT_EQ(p.track.size(), 1u);
    EXPECT_EQ(p.track[0].image_id, 5u);
    EXPECT_EQ(p.track[0].point2D_idx, 1u);
  }
}

TEST(Formats, ColmapReaderPrefersBinaryAndNormalizesQuaternions) {
  TempDir tmp("formats");
  const std::string dir = tmp / "model";
  WriteFile(dir + "/cameras.txt", "# comment\n1 PINHOLE 100 80 90 91 50.5 40.5\n");
  WriteFile(dir + "/images.txt", "\n1 2 0 0 0 1 2 3 1 a.jpg\n\n");
  WriteFile(dir + "/points3D.txt", "");
  const ColmapModel text = ReadColmapModel(dir);
  EXPECT_TRUE(text.images.at(1).cam_from_world.rotation.isApprox(Eigen::Quaterniond::Identity()));
  EXPECT_DOUBLE_EQ(text.images.at(1).cam_from_world.rotation.norm(), 1.0);

  ColmapModel other = text;
  other.images.at(1).name = "b.jpg";
  WriteColmapModelBinary(other, tmp / "bin");
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    fs::copy_file(tmp / (std::string("bin/") + file), dir + "/" + file);
  }
  EXPECT_EQ(ReadColmapModel(dir).images.at(1).name, "b.jpg");
}

TEST(Formats, TumRoundTrip) {
  const DatasetScene scene = MakeDatasetScene(6, 1, 3);
  TempDir tmp("formats");
  WriteTumTrajectory(tmp / "poses.txt", scene.poses);
  ExpectPosesEqual(scene.poses, ReadTumTrajectory(tmp / "poses.txt"));

  const std::vector<std::string> timestamps = {"1305031102.175304", "1305031102.211214",
                                               "1305031102.243211", "1305031102.275326",
                                               "1305031102.311267", "1305031102.343233"};
  WriteTumTrajectory(tmp / "timed.txt", scene.poses, timestamps);
  const PoseSet by_time = ReadTumTrajectory(tmp / "timed.txt");
  EXPECT_EQ(Names(by_time), timestamps);
  ExpectPosesEqual(scene.poses, ReadTumTrajectory(tmp / "timed.txt", Names(scene.poses)));

  WriteFile(tmp / "bad.txt", "# header\n0.1 1 2 3 0 0 0 1\n0.2 1 2 3 0 0 1\n");
  const std::string message = InputErrorOf([&] { ReadTumTrajectory(tmp / "bad.txt"); });
  EXPECT_NE(message.find(tmp / "bad.txt:3:"), std::string::npos) << message;
  const std::string count =
      InputErrorOf([&] { ReadTumTrajectory(tmp / "timed.txt", {"only_one.jpg"}); });
  EXPECT_NE(count.find("1 names"), std::string::npos) << count;
}

TEST(Formats, ImageNamesThatAreNotUtf8AreRefusedWithAPrintableMessage) {
  // A Linux file name is bytes; summary.json, COLMAP models and transforms.json hold UTF-8 names.
  TempDir tmp("formats");
  fs::create_directories(tmp / "model");
  WriteFile(tmp / "model/cameras.txt", "1 PINHOLE 100 80 90 90 50 40\n");
  WriteFile(tmp / "model/images.txt", "1 1 0 0 0 0 0 0 1 a\xff.jpg\n\n");
  WriteFile(tmp / "model/points3D.txt", "");
  const std::string message = InputErrorOf([&] { ReadPoseFile("colmap", tmp / "model"); });
  EXPECT_NE(message.find("image name 'a\\xFF.jpg' is not UTF-8 text (byte 0xFF at offset 1)"),
            std::string::npos)
      << message;
  EXPECT_EQ(InvalidUtf8Offset(message), std::string::npos);  // the message itself is printable

  EXPECT_EQ(EscapeInvalidUtf8("d\xe9mo \xc3\xa9 \xe2\x82"), "d\\xE9mo \xc3\xa9 \\xE2\\x82");
  EXPECT_EQ(std::string(InputError("x\xff").what()), "x\\xFF");
}

// Issue 47: an image named "\e]0;owned\a\e[31mred.jpg" retitled the terminal and recoloured the
// log through the features log line.
TEST(Formats, ControlCharactersAreShownNotObeyed) {
  EXPECT_EQ(EscapeControlCharacters("\x1b]0;owned\x07\x1b[31mred.jpg"),
            "\\x1B]0;owned\\x07\\x1B[31mred.jpg");
  EXPECT_EQ(EscapeControlCharacters("a\rb\x7f"), "a\\x0Db\\x7F");
  // C1 (U+009B is a one-character CSI for some terminals); newlines, tabs and text stay.
  EXPECT_EQ(EscapeControlCharacters("x\xc2\x9b"
                                    "2J \xc3\xa9\tline\n"),
            "x\\u009B2J \xc3\xa9\tline\n");
  // Bytes that are not UTF-8 are escaped first, so none is taken for the start of a C1 pair.
  EXPECT_EQ(EscapeControlCharacters("\x9b"), "\\x9B");
}

TEST(Formats, WarningsQuotingBytesThatAreNotUtf8StillSerialize) {
  // A warning may quote names and file contents in its message, images, pairs and details.
  const Warning warning{
      "code", "m\xff", {"i\xfe.jpg"}, {{"a\xfd", "b"}}, {{"names", {"n\x9b"}}, {"k\xfc", 1}}};
  const std::string text = WarningsToJson({warning}).dump();
  EXPECT_NE(text.find("m\\\\xFF"), std::string::npos) << text;
  EXPECT_NE(text.find("n\\\\x9B"), std::string::npos) << text;
  EXPECT_NE(text.find("k\\\\xFC"), std::string::npos) << text;
  EXPECT_NE(text.find("i\\\\xFE.jpg"), std::string::npos) << text;
}

std::string SharedData(const std::string& relative) {
  return std::string(RAYTIME_SHARED_DATA_DIR) + "/" + relative;
}

TEST(Formats, StrechaReadsRealCamera) {
  const std::string path = SharedData("strecha/fountain-P11/gt_dense_cameras/0000.jpg.camera");
  REQUIRE_SHARED_DATA(path);
  const StrechaCamera camera = ReadStrechaCamera(path);
  EXPECT_EQ(camera.intrinsics.width, 1536);
  EXPECT_EQ(camera.intrinsics.height, 1024);
  EXPECT_EQ(camera.intrinsics.params,
            (std::array<double, 8>{1379.74, 1382.08, 760.095, 503.155, 0, 0, 0, 0}));
  const Eigen::Matrix3d r = camera.world_from_cam.RotationMatrix();
  EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  Eigen::Matrix3d file_r;
  file_r << 0.450927, -0.0945642, -0.887537, -0.892535, -0.0401974, -0.449183, 0.00679989, 0.994707,
      -0.102528;
  EXPECT_LT((r - file_r).norm(), 1e-5);
  EXPECT_EQ(camera.world_from_cam.translation, Eigen::Vector3d(-7.28137, -7.57667, 0.204446));
}

TEST(Formats, StrechaReadsRealScene) {
  const std::string root = SharedData("strecha/fountain-P11");
  REQUIRE_SHARED_DATA(root);
  ImageSet images;
  PoseSet poses;
  ReadStrechaScene(root, &images, &poses);
  ASSERT_EQ(images.images.size(), 11u);
  EXPECT_EQ(images.images.front().name, "0000.jpg");
  EXPECT_EQ(Names(images), Names(poses));
  EXPECT_EQ(images.image_root, root + "/images");
}

TEST(Formats, StrechaRoundTrip) {
  const DatasetScene scene = MakeDatasetScene(1, 1, 4);
  const StrechaCamera camera{scene.images.cameras[0], scene.poses.world_from_cam.begin()->second};
  TempDir tmp("formats");
  WriteStrechaCamera(tmp / "a.jpg.camera", camera);
  const StrechaCamera read = ReadStrechaCamera(tmp / "a.jpg.camera");
  EXPECT_EQ(read.intrinsics, camera.intrinsics);
  EXPECT_LT(RotationDistance(read.world_from_cam.rotation, camera.world_from_cam.rotation),
            kPoseTolerance);
  EXPECT_EQ(read.world_from_cam.translation, camera.world_from_cam.translation);
}

// ---------------------------------------------------------------------------------------------
// Bad input.

TEST(FormatsBadInput, StrechaWrongNumberCount) {
  TempDir tmp("formats");
  std::string numbers;
  for (int i = 0; i < 20; ++i) numbers += "1 ";
  WriteFile(tmp / "0000.jpg.camera", numbers);
  const std::string message = InputErrorOf([&] { ReadStrechaCamera(tmp / "0000.jpg.camera"); });
  EXPECT_NE(message.find(tmp / "0000.jpg.camera"), std::string::npos) << message;
  EXPECT_NE(message.find("found 20 numbers"), std::string::npos) << message;
  EXPECT_NE(message.find("expected 26"), std::string::npos) << message;
}

// A sheared R was orthonormalized into a ground truth 8.5° off (issue 30, item 4): every reader
// of a rotation matrix refuses one that is not a rotation within kRotationMatrixTolerance.
TEST(FormatsBadInput, StrechaShearedRotationIsRefused) {
  TempDir tmp("formats");
  const std::string real =
      ReadTextFile(SharedData("strecha/fountain-P11/gt_dense_cameras/0000.jpg.camera"));
  // Line 5 is R's first row; 0.450927 -> 0.600927 shears R (|RᵀR - I| ~ 0.14).
  std::string sheared = real;
  const size_t at = sheared.find("0.450927000");
  ASSERT_NE(at, std::string::npos);
  sheared.replace(at, 11, "0.600927000");
  WriteFile(tmp / "0000.jpg.camera", sheared);
  const std::string message = InputErrorOf([&] { ReadStrechaCamera(tmp / "0000.jpg.camera"); });
  EXPECT_NE(message.find(tmp / "0000.jpg.camera:5:"), std::string::npos) << message;
  EXPECT_NE(message.find("not orthonormal"), std::string::npos) << message;
  // A reflection (one row negated) is named as such.
  std::string reflected = real;
  reflected.replace(reflected.find("0.450927000 -0.094564200 -0.887537000"), 37,
                    "-0.450927000 0.094564200 0.887537000");
  WriteFile(tmp / "0001.jpg.camera", reflected);
  const std::string reflection = InputErrorOf([&] { ReadStrechaCamera(tmp / "0001.jpg.camera"); });
  EXPECT_NE(reflection.find("determinant -1"), std::string::npos) << reflection;
  // The real file, 9 decimals, is within the tolerance.
  WriteFile(tmp / "0002.jpg.camera", real);
  EXPECT_NO_THROW(ReadStrechaCamera(tmp / "0002.jpg.camera"));
}

TEST(FormatsBadInput, TransformsJsonShearedRotationIsRefused) {
  TempDir tmp("formats");
  const std::string path = tmp / "transforms.json";
  // Unit columns, not orthogonal: a column-length check alone lets this through.
  WriteFile(path, R"({"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480,
    "frames": [
      {"file_path": "./images/a.jpg", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
      {"file_path": "./images/b.jpg", "transform_matrix": [[1,0.6,0,0],[0,0.8,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  const std::string message = InputErrorOf([&] { ReadTransformsJson(path, nullptr, nullptr); });
  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_NE(message.find("frame 1 (./images/b.jpg)"), std::string::npos) << message;
  EXPECT_NE(message.find("not orthonormal: |RᵀR - I| reaches 0.6"), std::string::npos) << message;
}

TEST(FormatsRotationMatrix, ToleranceSeparatesRoundingFromShear) {
  const Eigen::Matrix3d r = ExpSO3(Eigen::Vector3d(0.3, -1.2, 0.7));
  EXPECT_EQ(RotationMatrixProblem(r), "");
  // 6 decimals, as files carry them.
  const Eigen::Matrix3d rounded = (r * 1e6).array().round() / 1e6;
  EXPECT_EQ(RotationMatrixProblem(rounded), "");
  Eigen::Matrix3d shear = Eigen::Matrix3d::Identity();
  shear(0, 1) = 2e-3;
  EXPECT_NE(RotationMatrixProblem(r * shear).find("not orthonormal"), std::string::npos);
  EXPECT_NE(RotationMatrixProblem(-r).find("determinant -1"), std::string::npos);
  Eigen::Matrix3d nan = r;
  nan(1, 1) = std::nan("");
  EXPECT_NE(RotationMatrixProblem(nan).find("not finite"), std::string::npos);
}

TEST(FormatsBadInput, StrechaSceneMissingImage) {
  const DatasetScene scene = MakeDatasetScene(2, 1, 5);
  TempDir tmp("formats");
  for (const auto& [name, pose] : scene.poses.world_from_cam) {
    WriteStrechaCamera(tmp / ("scene/gt_dense_cameras/" + name + ".camera"),
                       {scene.images.cameras[0], pose});
  }
  WriteFile(tmp / "scene/images/frame_0000.jpg", "jpeg");
  const std::string message =
      InputErrorOf([&] { ReadStrechaScene(tmp / "scene", nullptr, nullptr); });
  EXPECT_NE(message.find("frame_0001.jpg"), std::string::npos) << message;
  EXPECT_EQ(message.find("frame_0000.jpg"), std::string::npos) << message;
}

TEST(FormatsBadInput, TransformsJson3x3Matrix) {
  TempDir tmp("formats");
  const std::string path = tmp / "transforms.json";
  WriteFile(path, R"({"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480,
    "frames": [
      {"file_path": "./images/a.jpg", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
      {"file_path": "./images/b.jpg", "transform_matrix": [[1,0,0],[0,1,0],[0,0,1]]}]})");
  const std::string message = InputErrorOf([&] { ReadTransformsJson(path, nullptr, nullptr); });
  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_NE(message.find("frame 1"), std::string::npos) << message;
  EXPECT_NE(message.find("must be 4x4, got 3x3"), std::string::npos) << message;

  WriteFile(path, R"({"w": 640, "h": 480, "frames": [{"file_path": "a.jpg",
    "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  const std::string no_focal = InputErrorOf([&] { ReadTransformsJson(path, nullptr, nullptr); });
  EXPECT_NE(no_focal.find("fl_x"), std::string::npos) << no_focal;
}

// Intrinsics as nerfstudio's dataparser reads them (nerfstudio_dataparser.py): a top-level value is
// every frame's and a frame's own is ignored; distortion is one group (any top-level term, or
// distortion_params [k1, k2, k3, k4, p1, p2], makes all of it the top level's); a frame's value
// counts only where the top level has none.
TEST(Formats, TransformsJsonIntrinsicsFollowNerfstudiosPrecedence) {
  TempDir tmp("formats");
  const std::string path = tmp / "transforms.json";
  WriteFile(path, R"({"fl_x": 500, "w": 640, "h": 480,
    "distortion_params": [0.1, 0.01, 0, 0, 0.001, 0.002],
    "frames": [
      {"file_path": "a.jpg", "fl_x": 900, "fl_y": 510, "cx": 321, "cy": 241, "k1": 0.5,
       "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
      {"file_path": "b.jpg", "fl_y": 520, "cx": 322, "cy": 242,
       "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,1],[0,0,0,1]]}]})");
  ImageSet images;
  PoseSet poses;
  ReadTransformsJson(path, &images, &poses);
  ASSERT_EQ(images.images.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    const CameraIntrinsics& camera = images.cameras[images.images[i].camera_index];
    SCOPED_TRACE(i);
    EXPECT_EQ(camera.params[kFx], 500.0);  // the top level's, not frame 0's 900
    EXPECT_EQ(camera.params[kFy], 510.0 + 10 * i);
    EXPECT_EQ(camera.params[kCx], 320.5 + i);  // nerfstudio's 321 + i, less half a pixel
    EXPECT_EQ(camera.params[kK1], 0.1);        // distortion_params, not frame 0's k1
    EXPECT_EQ(camera.params[kK2], 0.01);
    EXPECT_EQ(camera.params[kP1], 0.001);
    EXPECT_EQ(camera.params[kP2], 0.002);
  }

  WriteFile(path, R"({"fl_x": 500, "fl_y": 500, "w": 640, "h": 480,
    "distortion_params": [0.1, 0.01, 0.2, 0, 0, 0],
    "frames": [{"file_path": "a.jpg",
      "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  const std::string k3 = InputErrorOf([&] { ReadTransformsJson(path, nullptr, nullptr); });
  EXPECT_NE(k3.find("k3 is not supported"), std::string::npos) << k3;
  WriteFile(path, R"({"fl_x": 500, "fl_y": 500, "w": 640, "h": 480, "distortion_params": [0.1],
    "frames": [{"file_path": "a.jpg",
      "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  const std::string short_list = InputErrorOf([&] { ReadTransformsJson(path, nullptr, nullptr); });
  EXPECT_NE(short_list.find("distortion_params must be [k1, k2, k3, k4, p1, p2]"),
            std::string::npos)
      << short_list;
}

TEST(FormatsBadInput, ColmapMalformedTextLine) {
  const DatasetScene scene = MakeDatasetScene(3, 1, 6);
  TempDir tmp("formats");
  const std::string dir = tmp / "model";
  WriteColmapModelText(ToColmapModel(scene.images, scene.poses), dir);
  // images.txt: 4 header lines, then two lines per image; corrupt the second image's QX.
  std::string contents = ReadTextFile(dir + "/images.txt");
  std::vector<std::string> lines;
  for (size_t start = 0, end; start < contents.size(); start = end + 1) {
    end = contents.find('\n', start);
    lines.push_back(contents.substr(start, end - start));
  }
  ASSERT_EQ(lines[6].substr(0, 2), "2 ");
  lines[6].replace(lines[6].find(' ', 2) + 1, 0, "x");
  contents.clear();
  for (const auto& line : lines) contents += line + "\n";
  WriteFile(dir + "/images.txt", contents);
  std::string message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find(dir + "/images.txt:7:"), std::string::npos) << message;
  EXPECT_NE(message.find("QX"), std::string::npos) << message;

  WriteFile(dir + "/cameras.txt", "# header\n\n1 PINHOL 100 80 90 91 50 40\n");
  message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find(dir + "/cameras.txt:3:"), std::string::npos) << message;
  EXPECT_NE(message.find("unknown camera model 'PINHOL'"), std::string::npos) << message;

  WriteFile(dir + "/cameras.txt", "1 PINHOLE 100 80 90 91 50\n");
  message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find("cameras.txt:1: PINHOLE has 4 parameters, got 3"), std::string::npos)
      << message;
}

TEST(FormatsBadInput, ColmapTruncatedBinary) {
  const DatasetScene scene = MakeDatasetScene(3, 2, 7);
  TempDir tmp("formats");
  const std::string dir = tmp / "model";
  WriteColmapModelBinary(ToColmapModel(scene.images, scene.poses), dir);
  const std::string images = ReadTextFile(dir + "/images.bin");
  WriteFile(dir + "/images.bin", images.substr(0, images.size() - 5));
  std::string message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find(dir + "/images.bin"), std::string::npos) << message;
  EXPECT_NE(message.find("unexpected end of file"), std::string::npos) << message;
  EXPECT_NE(message.find("image 3 of 3"), std::string::npos) << message;

  // Every shorter prefix of every file, keypoints and tracks included, is an InputError.
  ColmapModel with_points = ToColmapModel(scene.images, scene.poses);
  with_points.images.at(1).points2D = {{1.5, 2.5}, {3.5, 4.5}};
  with_points.images.at(1).point3D_ids = {7, kInvalidPoint3DId};
  with_points.points3D[7].point3D_id = 7;
  with_points.points3D[7].track = {{1, 0}, {2, 0}};
  WriteColmapModelBinary(with_points, tmp / "full");
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const std::string full = ReadTextFile(tmp / "full/" + file);
    fs::copy(tmp / "full", tmp / "cut", fs::copy_options::overwrite_existing);
    for (size_t size = 0; size < full.size(); ++size) {
      WriteFile(tmp / "cut/" + file, full.substr(0, size));
      EXPECT_THROW(ReadColmapModelBinary(tmp / "cut"), InputError) << file << " cut to " << size;
    }
  }

  // An absurd count must be reported as truncation, not attempted as an allocation.
  WriteFile(dir + "/images.bin", std::string("\xff\xff\xff\xff\xff\xff\xff\x7f", 8));
  message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find("unexpected end of file"), std::string::npos) << message;

  std::string cameras = ReadTextFile(dir + "/cameras.bin");
  cameras[8 + 4] = 99;  // first camera's model id
  WriteFile(dir + "/cameras.bin", cameras);
  message = InputErrorOf([&] { ReadColmapModel(dir); });
  EXPECT_NE(message.find("unknown camera model id 99"), std::string::npos) << message;
  EXPECT_NE(message.find(dir + "/cameras.bin"), std::string::npos) << message;
}

TEST(FormatsBadInput, NameMismatchIsReported) {
  DatasetScene scene = MakeDatasetScene(3, 1, 8);
  scene.poses.world_from_cam["stray.jpg"] = Rigid3();
  TempDir tmp("formats");
  for (const auto& write : std::vector<std::function<void()>>{
           [&] { ToColmapModel(scene.images, scene.poses); },
           [&] { WriteTransformsJson(tmp / "t.json", scene.images, scene.poses); }}) {
    const std::string message = InputErrorOf(write);
    EXPECT_NE(message.find("stray.jpg"), std::string::npos) << message;
  }
  EXPECT_FALSE(fs::exists(tmp / "t.json"));
}

TEST(FormatsBadInput, WritersLeaveNoPartialFiles) {
  const DatasetScene scene = MakeDatasetScene(3, 1, 9);
  TempDir tmp("formats");
  const std::string dir = tmp / "model";
  const ColmapModel model = ToColmapModel(scene.images, scene.poses);
  WriteColmapModelText(model, dir);
  const std::string before = ReadTextFile(dir + "/images.txt");

  // A name COLMAP text cannot hold: the existing model stays as it was.
  ColmapModel bad = model;
  bad.images.begin()->second.name = "has space.jpg";
  EXPECT_THROW(WriteColmapModelText(bad, dir), InputError);
  EXPECT_EQ(ReadTextFile(dir + "/images.txt"), before);

  // The parent "directory" is a regular file: nothing can be created.
  WriteFile(tmp / "file", "x");
  EXPECT_ANY_THROW(WriteTumTrajectory(tmp / "file/poses.txt", scene.poses));
  EXPECT_ANY_THROW(WriteColmapModelBinary(model, tmp / "file/model"));

  // The rename onto the target fails (a directory is in the way) after the temporary file was
  // written: the temporary must be gone.
  fs::create_directories(tmp / "occupied.json/child");
  EXPECT_ANY_THROW(WriteTransformsJson(tmp / "occupied.json", scene.images, scene.poses));
  EXPECT_ANY_THROW(WriteStrechaCamera(tmp / "occupied.json", {scene.images.cameras[0], Rigid3()}));
  EXPECT_TRUE(fs::is_directory(tmp / "occupied.json/child"));

  EXPECT_THROW(WriteTumTrajectory(tmp / "t.txt", scene.poses, {"1", "2"}), std::invalid_argument);
  EXPECT_FALSE(fs::exists(tmp / "t.txt"));
  EXPECT_TRUE(TemporaryFilesBelow(tmp.path()).empty());
  std::vector<std::string> entries;
  for (const auto& entry : fs::directory_iterator(tmp.path())) {
    entries.push_back(entry.path().filename().string());
  }
  std::sort(entries.begin(), entries.end());
  EXPECT_EQ(entries, (std::vector<std::string>{"file", "model", "occupied.json"}));
}

}  // namespace
}  // namespace raytime
