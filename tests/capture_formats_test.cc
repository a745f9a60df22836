// The phone-capture readers (issue 10, docs/formats.md): fixtures written by test-only writers
// (tests/capture_fixtures.h) from the sample scene's ground truth perturbed by a known amount read
// back exactly; the two real captures in ../shared/data/captures (metadata and image headers only,
// no decoding); malformed files named in the error.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "formats/capture.h"
#include "formats/dataset.h"
#include "formats/npz.h"
#include "tests/capture_fixtures.h"
#include "tests/expect_pose.h"
#include "tests/input_error_of.h"
#include "tests/shared_data.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// The intrinsics the reader gives image `name` equal the fixture's K.
void ExpectCamera(const ImageSet& images, const std::string& name, const Eigen::Matrix3d& K,
                  int width, int height) {
  const int index = images.Find(name);
  ASSERT_GE(index, 0) << name;
  const ImageInfo& image = images.images[index];
  EXPECT_EQ(image.width, width);
  EXPECT_EQ(image.height, height);
  const CameraIntrinsics& camera = images.cameras[image.camera_index];
  EXPECT_NEAR(camera.fx(), K(0, 0), 1e-9) << name;
  EXPECT_NEAR(camera.fy(), K(1, 1), 1e-9) << name;
  EXPECT_NEAR(camera.cx(), K(0, 2), 1e-9) << name;
  EXPECT_NEAR(camera.cy(), K(1, 2), 1e-9) << name;
  EXPECT_FALSE(camera.HasDistortion());
}

Dataset Load(const std::string& format, const std::string& root) {
  DatasetOptions options;
  options.format = format;
  options.root = root;
  return LoadDataset(options);
}

// Every frame of `capture` is image names[i] with the fixture's pose, K and time.
void ExpectCaptureRead(const fixtures::Capture& capture, const Dataset& dataset,
                       const std::vector<std::string>& names) {
  ASSERT_EQ(dataset.images.images.size(), capture.frames.size());
  ASSERT_TRUE(dataset.capture.has_value());
  EXPECT_FALSE(dataset.ground_truth.has_value());
  ASSERT_EQ(dataset.capture->size(), capture.frames.size());
  // Per-frame intrinsics differ by 0.25 px: one camera per frame.
  EXPECT_EQ(dataset.images.cameras.size(), capture.frames.size());
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const fixtures::Frame& frame = capture.frames[i];
    ASSERT_TRUE(dataset.capture->Has(names[i])) << names[i];
    ExpectPoseNear(dataset.capture->world_from_cam.at(names[i]), frame.world_from_cam, 1e-9,
                   names[i]);
    ExpectCamera(dataset.images, names[i], frame.K, capture.width, capture.height);
    ASSERT_TRUE(dataset.timestamps.count(names[i])) << names[i];
    EXPECT_NEAR(dataset.timestamps.at(names[i]), frame.time_s, 1e-9) << names[i];
  }
}

std::vector<std::string> Names(const std::string& prefix, int n, const std::string& suffix) {
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) names.push_back(prefix + std::to_string(i) + suffix);
  return names;
}

TEST(CaptureFixtures, PerturbationIsTheKnownAmount) {
  // The fixtures' poses are the ground truth turned by exactly 2° and moved by exactly 5 cm.
  const Rigid3 identity;
  const Rigid3 moved = fixtures::Perturb(identity, 3);
  EXPECT_NEAR(DegreesFromRadians(RotationAngle(moved.rotation)), 2.0, 1e-12);
  EXPECT_NEAR(moved.translation.norm(), 0.05, 1e-12);
}

TEST(CaptureFormats, Record3dFixtureReadsBack) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("record3d");
  fixtures::WriteRecord3d(capture, dir.path().string());
  const Dataset dataset = Load("record3d", dir.path().string());
  ExpectCaptureRead(capture, dataset, Names("", 11, ".jpg"));
  EXPECT_EQ(dataset.images.image_root, dir / "rgb");
  EXPECT_TRUE(dataset.warnings.empty());
  // The pose part alone, as prior.format.
  const PoseSet poses = ReadPoseFile("record3d", dir / "metadata.json");
  ASSERT_EQ(poses.size(), 11u);
  ExpectPoseNear(poses.world_from_cam.at("7.jpg"), capture.frames[7].world_from_cam, 1e-9, "7");
}

TEST(CaptureFormats, Record3dMetadataAtAnotherResolutionIsRescaledWithAWarning) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("record3d_scaled");
  fixtures::WriteRecord3d(capture, dir.path().string(), 2.5);  // metadata for 1920x1280
  const Dataset dataset = Load("record3d", dir.path().string());
  ExpectCaptureRead(capture, dataset, Names("", 11, ".jpg"));
  ASSERT_EQ(dataset.warnings.size(), 1u);
  EXPECT_EQ(dataset.warnings[0].code, "intrinsics_rescaled");
  EXPECT_NE(dataset.warnings[0].message.find("1920x1280"), std::string::npos);
  EXPECT_EQ(dataset.warnings[0].images.size(), 11u);
}

TEST(CaptureFormats, Record3dMetadataOfAnotherAspectIsAnError) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("record3d_rotated");
  fixtures::WriteRecord3d(capture, dir.path().string());
  // Portrait metadata for landscape images: a rotation, not a rescale.
  std::string text;
  {
    std::ifstream in(dir / "metadata.json");
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  nlohmann::json metadata = nlohmann::json::parse(text);
  std::swap(metadata["w"], metadata["h"]);
  std::ofstream(dir / "metadata.json") << metadata.dump();
  {
    const std::string message = InputErrorOf([&] { Load("record3d", dir.path().string()); });
    EXPECT_NE(message.find("metadata.json"), std::string::npos) << message;
    EXPECT_NE(message.find("another aspect ratio"), std::string::npos) << message;
  }
}

TEST(CaptureFormats, PolycamFixtureReadsBackPreferringCorrectedCameras) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("polycam");
  fixtures::WritePolycam(capture, dir.path().string());
  const Dataset dataset = Load("polycam", dir.path().string());
  std::vector<std::string> names;
  for (const auto& frame : capture.frames) {
    names.push_back(std::to_string(std::llround(frame.time_s * 1e6)) + ".jpg");
  }
  ExpectCaptureRead(capture, dataset, names);
  EXPECT_EQ(dataset.images.image_root, dir / "keyframes/corrected_images");
  // Without the corrected folders, the ARKit cameras (moved by 1 m in the fixture) are read.
  fs::remove_all(dir / "keyframes/corrected_cameras");
  const PoseSet raw = ReadPoseFile("polycam", dir.path().string());
  EXPECT_NEAR(
      (raw.world_from_cam.at(names[4]).translation - capture.frames[4].world_from_cam.translation)
          .norm(),
      1.0, 1e-9);
}

TEST(CaptureFormats, Scanner3dFixtureReadsBackAndCountsPosesWithoutImages) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("scanner3d");
  fixtures::WriteScanner3d(capture, dir.path().string());
  const Dataset dataset = Load("scanner3d", dir.path().string());
  std::vector<std::string> names;
  for (int i = 0; i < 11; ++i) names.push_back(fixtures::Scanner3dName(i));
  ExpectCaptureRead(capture, dataset, names);
  EXPECT_EQ(dataset.num_poses_without_image, 20);
  // As a pose file every pose is read, also those without an image (31 = 11 + 20).
  EXPECT_EQ(ReadPoseFile("scanner3d", dir.path().string()).size(), 31u);
  EXPECT_TRUE(dataset.warnings.empty());

  // A photo whose frame file is missing was left out without a word (issue 30: 23 of 24 images).
  fs::remove(dir / (fixtures::Scanner3dName(4).substr(0, 11) + ".json"));
  const Dataset fewer = Load("scanner3d", dir.path().string());
  EXPECT_EQ(fewer.images.images.size(), 10u);
  ASSERT_EQ(fewer.warnings.size(), 1u);
  EXPECT_EQ(fewer.warnings[0].code, "images_without_frame");
  EXPECT_EQ(fewer.warnings[0].images, std::vector<std::string>{fixtures::Scanner3dName(4)});
  EXPECT_NE(fewer.warnings[0].message.find("1 image(s) in " + dir.path().string()),
            std::string::npos)
      << fewer.warnings[0].message;
}

TEST(CaptureFormats, NerfCaptureFixtureReadsBack) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("nerfcapture");
  fixtures::WriteNerfCapture(capture, dir.path().string());
  const Dataset dataset = Load("nerfcapture", dir.path().string());
  ExpectCaptureRead(capture, dataset, Names("", 11, ".jpg"));
  EXPECT_EQ(dataset.images.image_root, dir / "images");
  EXPECT_EQ(ReadPoseFile("nerfcapture", dir / "transforms.json").size(), 11u);
}

// ---- The paper's datasets. ----

// Every frame of `capture` is image names[i] with the fixture's K and, as ground truth, its pose.
void ExpectGroundTruthRead(const fixtures::Capture& capture, const Dataset& dataset,
                           const std::vector<std::string>& names) {
  ASSERT_EQ(dataset.images.images.size(), capture.frames.size());
  ASSERT_TRUE(dataset.ground_truth.has_value());
  ASSERT_EQ(dataset.ground_truth->size(), capture.frames.size());
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    ASSERT_TRUE(dataset.ground_truth->Has(names[i])) << names[i];
    ExpectPoseNear(dataset.ground_truth->world_from_cam.at(names[i]),
                   capture.frames[i].world_from_cam, 1e-9, names[i]);
    ExpectCamera(dataset.images, names[i], capture.frames[i].K, capture.width, capture.height);
  }
}

TEST(PaperDatasets, MobileBrickFixtureReadsBackAsGroundTruth) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("mobilebrick");
  fixtures::WriteMobileBrick(capture, dir.path().string());
  const Dataset dataset = Load("mobilebrick", dir.path().string());
  std::vector<std::string> names;
  for (int i = 0; i < 11; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "%06d.jpg", i);
    names.push_back(name);
  }
  ExpectGroundTruthRead(capture, dataset, names);
  EXPECT_FALSE(dataset.capture.has_value());
  EXPECT_EQ(ReadPoseFile("mobilebrick", dir.path().string()).size(), 11u);

  // With PoRF's cameras_arkit.npz the ARKit poses are the capture poses.
  const Rigid3 arkit_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d(0, 1, 1).normalized())),
      Eigen::Vector3d(0.5, -1, 2));
  TempDir with_arkit("mobilebrick_arkit");
  fixtures::WriteMobileBrick(capture, with_arkit.path().string(), &arkit_from_world);
  const Dataset arkit = Load("mobilebrick", with_arkit.path().string());
  ExpectGroundTruthRead(capture, arkit, names);
  ASSERT_TRUE(arkit.capture.has_value());
  for (int i = 0; i < 11; ++i) {
    ExpectPoseNear(arkit.capture->world_from_cam.at(names[i]),
                   arkit_from_world * capture.frames[i].world_from_cam, 1e-9, names[i]);
  }
}

TEST(PaperDatasets, ScanNetPPFixtureReadsArkitPosesAndAlignedGroundTruth) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  // ARKit's own world: turned 30° about z and moved.
  const Rigid3 arkit_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.5236, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(1, 2, 3));
  std::vector<std::string> names;
  for (int i = 0; i < 11; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06d.jpg", i);
    names.push_back(name);
  }
  for (const bool arkit_axes : {false, true}) {
    TempDir dir("scannetpp");
    fixtures::WriteScanNetPP(capture, dir.path().string(), arkit_from_world, arkit_axes);
    const Dataset dataset = Load("scannetpp_iphone", dir.path().string());
    ExpectGroundTruthRead(capture, dataset, names);
    EXPECT_EQ(dataset.num_poses_without_image, 1);
    ASSERT_TRUE(dataset.capture.has_value());
    for (int i = 0; i < 11; ++i) {
      ExpectPoseNear(dataset.capture->world_from_cam.at(names[i]),
                     arkit_from_world * capture.frames[i].world_from_cam, 1e-9,
                     names[i] + (arkit_axes ? " (ARKit axes)" : " (OpenCV axes)"));
      EXPECT_NEAR(dataset.timestamps.at(names[i]), capture.frames[i].time_s, 1e-12);
    }
  }
}

TEST(PaperDatasets, ArkitScenesFixtureJoinsFramesToTheTrajectoryByTime) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("arkitscenes");
  fixtures::WriteArkitScenes(capture, dir.path().string(), "41069021");
  const Dataset dataset = Load("arkitscenes", dir.path().string());
  std::vector<std::string> names;
  for (const auto& frame : capture.frames) {
    names.push_back(fixtures::ArkitScenesName("41069021", frame.time_s) + ".png");
  }
  ExpectGroundTruthRead(capture, dataset, names);
  EXPECT_FALSE(dataset.capture.has_value());
  EXPECT_TRUE(dataset.warnings.empty());
  // A frame 0.3 s after the last pose is reported and left out.
  fs::copy_file(dir / ("lowres_wide/" + names[0]), dir / "lowres_wide/41069021_101.300.png");
  fs::copy_file(
      dir / ("lowres_wide_intrinsics/" + names[0].substr(0, names[0].size() - 4) + ".pincam"),
      dir / "lowres_wide_intrinsics/41069021_101.300.pincam");
  const Dataset more = Load("arkitscenes", dir.path().string());
  EXPECT_EQ(more.images.images.size(), 11u);
  ASSERT_EQ(more.warnings.size(), 1u);
  EXPECT_EQ(more.warnings[0].code, "unjoined_frames");
  EXPECT_EQ(more.warnings[0].images, std::vector<std::string>{"41069021_101.300.png"});
}

TEST(PaperDatasets, LamarFixtureReadsRigPosesAndTheAlignment) {
  const Rigid3 arkit_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(-0.3, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(-4, 0.5, 2));
  const Rigid3 rig_from_cam(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                            Eigen::Vector3d(0.01, -0.02, 0.005));
  // One camera in sensors.txt: every frame has the first frame's K.
  fixtures::Capture capture = fixtures::SampleCapture();
  for (auto& frame : capture.frames) frame.K = capture.frames.front().K;
  TempDir dir("lamar");
  fixtures::WriteLamar(capture, dir.path().string(), arkit_from_world, rig_from_cam);
  const Dataset dataset = Load("lamar", dir.path().string());
  std::vector<std::string> names;
  for (const auto& frame : capture.frames) names.push_back(fixtures::LamarName(frame.time_s));
  ExpectGroundTruthRead(capture, dataset, names);
  ASSERT_TRUE(dataset.capture.has_value());
  for (size_t i = 0; i < names.size(); ++i) {
    ExpectPoseNear(dataset.capture->world_from_cam.at(names[i]),
                   arkit_from_world * capture.frames[i].world_from_cam, 1e-9, names[i]);
    EXPECT_NEAR(dataset.timestamps.at(names[i]), capture.frames[i].time_s, 1e-9);
  }
  // The image at a timestamp 898 s after the trajectory: reported, not a frame.
  ASSERT_EQ(dataset.warnings.size(), 1u);
  EXPECT_EQ(dataset.warnings[0].code, "unjoined_frames");
  EXPECT_EQ(dataset.warnings[0].images, std::vector<std::string>{"cam0/999000000.jpg"});
  EXPECT_EQ(dataset.warnings[0].details["num_after_end"], 1);
  EXPECT_EQ(dataset.images.cameras.size(), 1u);
}

// ---- Malformed files: the error names the file and what was expected. ----

void ExpectInputError(const std::function<void()>& load, const std::vector<std::string>& parts) {
  {
    const std::string message = InputErrorOf([&] { load(); });
    for (const std::string& part : parts) {
      EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
    }
  }
}

TEST(CaptureFormatsBadInput, Record3dMalformedMetadata) {
  TempDir dir("record3d_bad");
  const std::string metadata = dir / "metadata.json";
  std::ofstream(metadata) << "{\"w\": 1440, \"h\": 1920, \"K\": [1, 2, 3], \"poses\": []}";
  ExpectInputError([&] { Load("record3d", dir.path().string()); },
                   {metadata, "\"K\" must be an array of 9 numbers, got an array of 3"});
  std::ofstream(metadata) << "{\"w\": 1440, \"h\": 1920, \"K\": [1,0,0,0,1,0,0,0,1], "
                             "\"poses\": [[0, 0, 0, 1, 0, 0]]}";
  ExpectInputError([&] { Load("record3d", dir.path().string()); },
                   {metadata, "poses[0]", "7 numbers"});
  std::ofstream(metadata) << "{\"w\": 1440, \"h\": 1920, \"K\": [1,0,0,0,1,0,0,0,1], "
                             "\"poses\": [[0, 0, 0, 1, 0, 0, 0]], \"frameTimestamps\": [0, 1]}";
  ExpectInputError([&] { Load("record3d", dir.path().string()); },
                   {metadata, "frameTimestamps", "one entry per pose (1)"});
  std::ofstream(metadata) << "{\"w\": 1440,";
  ExpectInputError([&] { Load("record3d", dir.path().string()); }, {metadata, "not valid JSON"});
  // A number beyond double: nlohmann's out_of_range, not its parse_error (capture_record3d fuzzer;
  // every JSON capture reader goes through ReadJsonFile).
  std::ofstream(metadata) << "{\"w\": 1e999, \"h\": 1920}";
  ExpectInputError([&] { Load("record3d", dir.path().string()); },
                   {metadata, "not valid JSON", "1e999"});
}

TEST(CaptureFormatsBadInput, Scanner3dMalformedFrame) {
  TempDir dir("scanner3d_bad");
  const std::string frame = dir / "frame_00000.json";
  std::ofstream(frame) << "{\"cameraPoseARFrame\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], "
                          "\"intrinsics\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"time\": 0}";
  ExpectInputError([&] { Load("scanner3d", dir.path().string()); },
                   {frame, "\"cameraPoseARFrame\" must be an array of 16 numbers"});
  std::ofstream(frame) << "{\"cameraPoseARFrame\": [2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, "
                          "1], \"intrinsics\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"time\": 0}";
  ExpectInputError([&] { Load("scanner3d", dir.path().string()); },
                   {frame, "not orthonormal: |RᵀR - I| reaches 3"});
}

TEST(CaptureFormatsBadInput, PolycamCameraWithoutTransformRow) {
  TempDir dir("polycam_bad");
  fs::create_directories(dir / "keyframes/cameras");
  const std::string camera = dir / "keyframes/cameras/1000.json";
  std::ofstream(camera) << "{\"fx\": 1, \"fy\": 1, \"cx\": 0, \"cy\": 0, \"width\": 4, "
                           "\"height\": 3, \"t_00\": 1, \"t_01\": 0, \"t_02\": 0, \"t_03\": 0}";
  ExpectInputError([&] { Load("polycam", dir.path().string()); }, {camera, "missing \"t_10\""});
}

// A width or height beyond an int was cast to int (undefined behaviour; lamar and arkitscenes also
// took negative and fractional sizes): found by capture_lamar, the same cast fixed in every reader.
TEST(CaptureFormatsBadInput, ImageSizesBeyondAnIntNameTheFile) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("sizes_bad");
  const auto replace = [](const std::string& path, const std::string& from, const std::string& to) {
    std::ifstream in(path);
    std::string text((std::istreambuf_iterator<char>(in)), {});
    const size_t at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from << " not in " << path;
    text.replace(at, from.size(), to);
    std::ofstream(path) << text;
  };
  fixtures::WriteRecord3d(capture, dir / "record3d");
  replace(dir / "record3d/metadata.json", "\"w\":768", "\"w\":10000000000");
  ExpectInputError([&] { Load("record3d", dir / "record3d"); },
                   {dir / "record3d/metadata.json",
                    "\"w\" must be a positive whole number of pixels (at most 1e9), got 1e+10"});

  fixtures::WriteLamar(capture, dir / "lamar", Rigid3(), Rigid3());
  replace(dir / "lamar/sensors.txt", "768, 512,", "768, 760505595060751,");
  ExpectInputError(
      [&] { Load("lamar", dir / "lamar"); },
      {dir / "lamar/sensors.txt:2", "height (field 6) must be a positive whole number"});
  replace(dir / "lamar/sensors.txt", "768, 760505595060751,", "768, -512,");
  ExpectInputError([&] { Load("lamar", dir / "lamar"); },
                   {dir / "lamar/sensors.txt:2", "height (field 6)", "got -512"});

  fixtures::WriteArkitScenes(capture, dir / "arkitscenes", "41069021");
  const std::string pincam = dir / "arkitscenes/lowres_wide_intrinsics/41069021_100.000.pincam";
  replace(pincam, "768 512", "768.5 512");
  ExpectInputError([&] { Load("arkitscenes", dir / "arkitscenes"); },
                   {pincam, "width (the first number) must be a positive whole number"});
}

// An axis-angle whose norm overflows made a NaN ground-truth pose without an error (found by
// capture_arkitscenes, which stops on non-finite poses).
TEST(CaptureFormatsBadInput, ArkitScenesPoseThatOverflowsNamesTheLine) {
  fixtures::Capture capture = fixtures::SampleCapture();
  capture.frames.resize(2);
  TempDir dir("arkitscenes_overflow");
  fixtures::WriteArkitScenes(capture, dir.path().string(), "41069021");
  std::ofstream(dir / "lowres_wide.traj")
      << "100 0 0 0 0 0 0\n100.05 1e200 0 0 0 0 0\n100.1 0 0 0 0 0 0\n";
  ExpectInputError([&] { Load("arkitscenes", dir.path().string()); },
                   {dir / "lowres_wide.traj:2", "not finite once converted"});
  ExpectInputError([&] { ReadPoseFile("arkitscenes", dir.path().string()); },
                   {dir / "lowres_wide.traj:2", "not finite once converted"});
}

// Two microsecond timestamps beyond 2^53 that are the same double in seconds reached the join by
// time, whose error ("two trajectory poses at time ...") escaped without the file and line.
TEST(CaptureFormatsBadInput, LamarTimestampsBeyond2To52MicrosecondsNameTheLine) {
  fixtures::Capture capture = fixtures::SampleCapture();
  TempDir dir("lamar_timestamps");
  fixtures::WriteLamar(capture, dir.path().string(), Rigid3(), Rigid3());
  std::ofstream(dir / "trajectories.txt") << "# timestamp, device_id, qw, qx, qy, qz, tx, ty, tz\n"
                                             "9007199254740992000, rig0, 1, 0, 0, 0, 0, 0, 0\n"
                                             "9007199254740992001, rig0, 1, 0, 0, 0, 0, 0, 0\n";
  ExpectInputError([&] { Load("lamar", dir.path().string()); },
                   {dir / "trajectories.txt:2", "beyond 2^52 microseconds"});
}

// The npz fuzzer's reproducers (tests/fuzz/corpus/npz/crash-*): each an InputError naming the
// entry, not an overflowing read, an escaping std::invalid_argument (std::stol), a negative or
// overflowing allocation.
TEST(CaptureFormatsBadInput, NpzDamagedArchivesNameTheEntry) {
  const std::string corpus = std::string(RAYTIME_SOURCE_DIR) + "/tests/fuzz/corpus/npz/";
  const auto read = [&](const std::string& file) { return [=] { ReadNpz(corpus + file); }; };
  ExpectInputError(read("crash-name-past-end.npz"), {"runs past the end of the file"});
  ExpectInputError(read("crash-shape-not-a-number.npz"),
                   {"entry world_mat_0", "shape (4, x) is not 1-D or 2-D"});
  ExpectInputError(read("crash-shape-unclosed.npz"), {"entry world_mat_0", "no 'shape'"});
  ExpectInputError(read("crash-shape-negative.npz"), {"entry world_mat_0", "shape (-1, -1)"});
  ExpectInputError(read("crash-shape-overflow.npz"), {"entry world_mat_0", "is too large"});
  ExpectInputError(read("header-length-past-entry.npz"),
                   {"entry world_mat_0", "truncated .npy header"});
  // The fixture's archive still reads: a 4x4 per world_mat and scale_mat.
  const auto arrays = ReadNpz(corpus + "cameras_arkit.npz");
  ASSERT_EQ(arrays.count("world_mat_2"), 1u);
  EXPECT_EQ(arrays.at("world_mat_2").rows(), 4);
  EXPECT_EQ(arrays.at("world_mat_2").cols(), 4);
}

TEST(CaptureFormatsBadInput, DatasetFormatNamesTheValidOnes) {
  TempDir dir("format_bad");
  ExpectInputError([&] { Load("record3", dir.path().string()); },
                   {"record3", "did you mean 'record3d'"});
}

// ---- The real captures of ../shared/data/captures (metadata and headers only). ----

const std::string kCaptures = std::string(RAYTIME_SHARED_DATA_DIR) + "/captures";

TEST(RealCaptures, Scanner3dChairHas24FramesOf70Poses) {
  const std::string root = kCaptures + "/3dscanner-chair";
  REQUIRE_SHARED_DATA(root);
  const Dataset dataset = Load("scanner3d", root);
  ASSERT_EQ(dataset.images.images.size(), 24u);
  EXPECT_EQ(dataset.num_poses_without_image, 46);
  ASSERT_TRUE(dataset.capture.has_value());
  EXPECT_EQ(dataset.capture->size(), 24u);
  EXPECT_FALSE(dataset.ground_truth.has_value());
  EXPECT_EQ(dataset.timestamps.size(), 24u);
  EXPECT_EQ(ReadPoseFile("scanner3d", root).size(), 70u);
  for (const ImageInfo& image : dataset.images.images) {
    EXPECT_EQ(image.width, 1920);
    EXPECT_EQ(image.height, 1440);
    const CameraIntrinsics& camera = dataset.images.cameras[image.camera_index];
    EXPECT_NEAR(camera.fx(), 1447.7, 2.0) << image.name;
    EXPECT_NEAR(camera.fy(), camera.fx(), 1e-6) << image.name;
    EXPECT_NEAR(camera.cx(), 960, 20) << image.name;
    EXPECT_NEAR(camera.cy(), 720, 40) << image.name;
  }
  // A walk once around a chair: consecutive kept frames a few cm to ~0.5 m apart, the whole
  // path a few metres, and the cameras look at a common point (the chair): optical axes converge.
  double path = 0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  const auto& poses = dataset.capture->world_from_cam;
  for (auto it = std::next(poses.begin()); it != poses.end(); ++it) {
    path += (it->second.translation - std::prev(it)->second.translation).norm();
  }
  for (const auto& [name, pose] : poses) centroid += pose.translation / poses.size();
  EXPECT_GT(path, 1.5);
  EXPECT_LT(path, 5.0);
  int looking_inward = 0;
  for (const auto& [name, pose] : poses) {
    const Eigen::Vector3d forward = pose.rotation * Eigen::Vector3d::UnitZ();  // OpenCV z
    if (forward.dot(centroid - pose.translation) > 0) ++looking_inward;
  }
  EXPECT_GE(looking_inward, 22) << "cameras should face the chair at the path's centre";
}

TEST(RealCaptures, Record3dDeskHas457PortraitFramesWithPerFrameIntrinsics) {
  const std::string root = kCaptures + "/record3d-desk";
  REQUIRE_SHARED_DATA(root);
  const Dataset dataset = Load("record3d", root);
  ASSERT_EQ(dataset.images.images.size(), 457u);
  ASSERT_TRUE(dataset.capture.has_value());
  EXPECT_EQ(dataset.capture->size(), 457u);
  EXPECT_EQ(dataset.num_poses_without_image, 0);
  EXPECT_TRUE(dataset.warnings.empty() ||
              dataset.warnings.front().code == "cameras_merged");  // no rescale: sizes agree
  EXPECT_GT(dataset.images.cameras.size(), 1u);  // the focal length drifts over the capture
  for (const ImageInfo& image : dataset.images.images) {
    ASSERT_EQ(image.width, 1440);
    ASSERT_EQ(image.height, 1920);
    const CameraIntrinsics& camera = dataset.images.cameras[image.camera_index];
    EXPECT_NEAR(camera.fx(), 1454, 10) << image.name;
    EXPECT_NEAR(camera.cx(), 720, 20) << image.name;  // portrait: cx near half the width
    EXPECT_NEAR(camera.cy(), 960, 20) << image.name;
  }
  // 60 fps, 7.6 s.
  ASSERT_EQ(dataset.timestamps.size(), 457u);
  EXPECT_NEAR(dataset.timestamps.at("1.jpg") - dataset.timestamps.at("0.jpg"), 1.0 / 60, 1e-3);
  EXPECT_NEAR(dataset.timestamps.at("456.jpg"), 7.6, 0.1);
  // A smooth path of about a metre: no frame-to-frame jump above 2 cm or 3° at 60 fps.
  double path = 0, largest_step = 0, largest_turn_deg = 0;
  for (int i = 1; i < 457; ++i) {
    const Rigid3& a = dataset.capture->world_from_cam.at(std::to_string(i - 1) + ".jpg");
    const Rigid3& b = dataset.capture->world_from_cam.at(std::to_string(i) + ".jpg");
    const double step = (b.translation - a.translation).norm();
    path += step;
    largest_step = std::max(largest_step, step);
    largest_turn_deg =
        std::max(largest_turn_deg, DegreesFromRadians(RotationDistance(a.rotation, b.rotation)));
  }
  EXPECT_GT(path, 0.5);
  EXPECT_LT(path, 2.5);
  EXPECT_LT(largest_step, 0.02);
  EXPECT_LT(largest_turn_deg, 3.0);
}

}  // namespace
}  // namespace raytime
