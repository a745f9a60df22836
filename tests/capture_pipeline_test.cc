// Captures through the stages (issue 10): the dataset stage writing the capture's poses as pose
// set "capture" and saying what the dataset has; the video path (stray: frames decoded from
// rgb.mp4 and joined to odometry at another rate by timestamp); the prior stage's `source:
// capture` and its errors on datasets without capture poses or ground truth.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/provenance.h"
#include "formats/dataset.h"
#include "formats/stray.h"
#include "frontend/video_frames.h"
#include "pipelines/stage.h"
#include "tests/capture_fixtures.h"
#include "tests/expect_pose.h"
#include "tests/input_error_of.h"
#include "tests/run_stage.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// The geodesic between two poses, independent of core/timestamps.
Rigid3 Between(const Rigid3& a, const Rigid3& b, double fraction) {
  const Eigen::Matrix3d ra = a.RotationMatrix(), rb = b.RotationMatrix();
  const Eigen::AngleAxisd relative(ra.transpose() * rb);
  return Rigid3(
      Eigen::Quaterniond(
          ra * Eigen::AngleAxisd(fraction * relative.angle(), relative.axis()).toRotationMatrix()),
      a.translation + fraction * (b.translation - a.translation));
}

// The pose the odometry rows give at time t (on their clock).
Rigid3 OdometryAt(const std::vector<fixtures::OdometryRow>& rows, double t) {
  for (size_t j = 0; j + 1 < rows.size(); ++j) {
    if (std::abs(rows[j].time_s - t) < 1e-9) return rows[j].world_from_cam;
    if (rows[j].time_s < t && t < rows[j + 1].time_s) {
      return Between(rows[j].world_from_cam, rows[j + 1].world_from_cam,
                     (t - rows[j].time_s) / (rows[j + 1].time_s - rows[j].time_s));
    }
  }
  return rows.back().world_from_cam;
}

struct StrayRun {
  Dataset dataset;
  std::vector<fixtures::OdometryRow> rows;
};

// Writes a stray fixture (video at 10 fps, odometry at 25 Hz) and runs what the dataset stage
// runs on it.
bool RunStray(const TempDir& dir, double capture_scale, int capture_width, StrayRun* run) {
  const fixtures::Capture capture = fixtures::SampleCapture();
  if (!fixtures::WriteStray(capture, dir / "stray", 10.0, 25.0, capture_scale, &run->rows)) {
    return false;
  }
  DatasetOptions options;
  options.format = "stray";
  options.root = dir / "stray";
  run->dataset = LoadDataset(options);
  EXPECT_TRUE(run->dataset.video.has_value());
  EXPECT_TRUE(run->dataset.images.images.empty());
  VideoFramesOptions video;
  video.video = run->dataset.video->path;
  VideoFramesSummary summary;
  std::vector<DecodedFrame> decoded;
  const ImageSet frames = ExtractVideoFrames(video, dir / "frames", &summary, &decoded);
  EXPECT_EQ(frames.images.size(), 11u);
  AttachVideoFrames(frames, decoded, capture_width, options.timestamps, &run->dataset);
  return true;
}

TEST(CaptureVideo, StrayFramesJoinOdometryAtAnotherRateByTimestamp) {
  TempDir dir("stray");
  StrayRun run;
  if (!RunStray(dir, 1.0, 0, &run)) GTEST_SKIP() << "this OpenCV cannot write MPEG-4 video";
  const fixtures::Capture capture = fixtures::SampleCapture();
  const Dataset& dataset = run.dataset;
  ASSERT_EQ(dataset.images.images.size(), 11u);
  ASSERT_TRUE(dataset.capture.has_value());
  EXPECT_TRUE(dataset.warnings.empty());
  ASSERT_EQ(dataset.images.cameras.size(), 1u);
  const CameraIntrinsics& camera = dataset.images.cameras[0];
  EXPECT_NEAR(camera.fx(), capture.frames[0].K(0, 0), 1e-9);
  EXPECT_NEAR(camera.cy(), capture.frames[0].K(1, 2), 1e-9);
  for (int k = 0; k < 11; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06d.jpg", k);
    ASSERT_TRUE(dataset.capture->Has(name)) << name;
    // Frame k is shown at k / 10 s: 100 + k / 10 on the odometry's clock; even frames fall on an
    // odometry row (every 0.04 s), odd ones between two rows.
    ASSERT_TRUE(dataset.timestamps.count(name));
    EXPECT_NEAR(dataset.timestamps.at(name), 100.0 + 0.1 * k, 1e-6) << name;
    ExpectPoseNear(dataset.capture->world_from_cam.at(name),
                   OdometryAt(run.rows, dataset.timestamps.at(name)), 1e-9, name);
    // ... which is within the interpolation's reach of the capture's own pose for the frame.
    ExpectPoseNear(dataset.capture->world_from_cam.at(name), capture.frames[k].world_from_cam,
                   k % 2 == 0 ? 1e-6 : 0.1, name);
  }
  // The pose part alone, named as the decoded frames.
  const PoseSet poses = ReadPoseFile("stray", dir / "stray");
  EXPECT_EQ(poses.size(), 11u);  // 26 rows naming 11 frames, the first row of each kept
}

TEST(CaptureVideo, StrayIntrinsicsAtTheCaptureResolutionAreRescaled) {
  TempDir dir("stray_scaled");
  StrayRun run;
  if (!RunStray(dir, 2.0, 1536, &run)) GTEST_SKIP() << "this OpenCV cannot write MPEG-4 video";
  const fixtures::Capture capture = fixtures::SampleCapture();
  const CameraIntrinsics& exact = run.dataset.images.cameras.at(0);
  EXPECT_NEAR(exact.fx(), capture.frames[0].K(0, 0), 1e-9);
  EXPECT_NEAR(exact.cx(), capture.frames[0].K(0, 2), 1e-9);
  ASSERT_EQ(run.dataset.warnings.size(), 1u);
  EXPECT_EQ(run.dataset.warnings[0].code, "intrinsics_rescaled");
  EXPECT_EQ(run.dataset.warnings[0].details["estimated"], false);

  // Without dataset.capture_width the scale is estimated from the principal point.
  TempDir again("stray_estimated");
  ASSERT_TRUE(RunStray(again, 2.0, 0, &run));
  const CameraIntrinsics& estimated = run.dataset.images.cameras.at(0);
  EXPECT_NEAR(estimated.fx() / capture.frames[0].K(0, 0), 1.0, 0.02);
  ASSERT_EQ(run.dataset.warnings.size(), 1u);
  EXPECT_EQ(run.dataset.warnings[0].details["estimated"], true);
}

// A Stray Scanner folder in dir/stray: `camera_matrix` as camera_matrix.csv, `odometry` as
// odometry.csv and a placeholder video; the dataset options that read it.
DatasetOptions StrayFolder(const TempDir& dir, const std::string& camera_matrix,
                           const std::string& odometry) {
  fs::create_directories(dir / "stray");
  std::ofstream(dir / "stray/rgb.mp4") << "not a video";
  std::ofstream(dir / "stray/camera_matrix.csv") << camera_matrix;
  std::ofstream(dir / "stray/odometry.csv") << odometry;
  DatasetOptions options;
  options.format = "stray";
  options.root = dir / "stray";
  return options;
}

TEST(CaptureVideo, OdometryErrorsNameTheLine) {
  TempDir dir("stray_bad");
  const DatasetOptions options = StrayFolder(dir, "1, 0, 2\n0, 1, 2\n0, 0, 1\n",
                                             "timestamp, frame, x, y, z, qx, qy, qz, qw\n"
                                             "0.0, 0, 0, 0, 0, 0, 0, 0, 1\n"
                                             "0.1, 1, 0, 0, zero, 0, 0, 0, 1\n");
  {
    const std::string message = InputErrorOf([&] { LoadDataset(options); });
    EXPECT_NE(message.find("odometry.csv:3"), std::string::npos) << message;
    EXPECT_NE(message.find("column 'z'"), std::string::npos) << message;
  }
  std::ofstream(dir / "stray/odometry.csv") << "x, y, z, qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 1\n";
  {
    const std::string message = InputErrorOf([&] { LoadDataset(options); });
    EXPECT_NE(message.find("odometry.csv:1"), std::string::npos) << message;
    EXPECT_NE(message.find("timestamp, frame, x, y, z, qx, qy, qz, qw"), std::string::npos)
        << message;
  }
}

// Decoded frames without a video (AttachVideoFrames only needs their names, size and times):
// `count` frames of width x height at 10 fps, frame k at k / 10 s.
void AttachFrames(int count, int width, int height, int capture_width, Dataset* dataset) {
  ImageSet frames;
  frames.image_root = "frames";
  CameraIntrinsics camera;
  camera.width = width;
  camera.height = height;
  frames.cameras.push_back(camera);
  std::vector<DecodedFrame> decoded;
  for (int k = 0; k < count; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06d.jpg", k);
    frames.images.push_back({name, width, height, 0});
    decoded.push_back({k, 0.1 * k});
  }
  AttachVideoFrames(frames, decoded, capture_width, TimestampJoinOptions(), dataset);
}

// The rescale went through the capture size rounded to whole pixels, which could round to 0 and
// divide by it; and a principal point in the corner (rx = ry = 0) passed the aspect check as NaN
// and made the scale infinite. Both gave non-finite intrinsics without an error (capture_stray).
TEST(CaptureVideo, StrayRescaleStaysFiniteOrNamesTheFile) {
  TempDir dir("stray_rescale");
  // capture_width 1 for 640x1 frames: the capture's height, 1 / 640 px, rounded to 0.
  const DatasetOptions options =
      StrayFolder(dir, "2, 0, 0.5\n0, 2, 0.25\n0, 0, 1\n",
                  "timestamp, frame, x, y, z, qx, qy, qz, qw\n0.0, 0, 0, 0, 0, 0, 0, 0, 1\n"
                  "0.1, 1, 0, 0, 1, 0, 0, 0, 1\n0.2, 2, 0, 0, 2, 0, 0, 0, 1\n");
  Dataset dataset = LoadDataset(options);
  AttachFrames(3, 640, 1, 1, &dataset);
  ASSERT_EQ(dataset.images.cameras.size(), 1u);
  const CameraIntrinsics& camera = dataset.images.cameras[0];
  EXPECT_DOUBLE_EQ(camera.fx(), 2 * 640.0);
  EXPECT_DOUBLE_EQ(camera.fy(), 2 * 640.0);
  EXPECT_DOUBLE_EQ(camera.cx(), 0.5 * 640 - 0.5);  // ARKit's 0.5 from the corner, scaled
  EXPECT_DOUBLE_EQ(camera.cy(), 0.25 * 640 - 0.5);
  ASSERT_EQ(dataset.warnings.size(), 1u);
  EXPECT_EQ(dataset.warnings[0].code, "intrinsics_rescaled");

  std::ofstream(dir / "stray/camera_matrix.csv") << "689.87, 0, 0\n0, 691.04, 0\n0, 0, 1\n";
  dataset = LoadDataset(options);
  {
    const std::string message = InputErrorOf([&] { AttachFrames(3, 768, 512, 0, &dataset); });
    EXPECT_NE(message.find("camera_matrix.csv"), std::string::npos) << message;
    EXPECT_NE(message.find("is not near the centre"), std::string::npos) << message;
  }
}

// ---- The dataset and prior stages. ----

nlohmann::json RunStage(const std::string& type, const std::string& options, const TempDir& dir,
                        const std::map<std::string, std::string>& artifacts) {
  return RunStageInProcess(type, options, dir.path().string(), artifacts);
}

TEST(CaptureStages, DatasetStageWritesTheCapturePosesAndSaysWhatItHas) {
  TempDir dir("dataset_stage");
  fixtures::WriteScanner3d(fixtures::SampleCapture(), dir / "scan");
  const nlohmann::json summary =
      RunStage("dataset", "{format: scanner3d, root: " + (dir / "scan") + "}", dir, {});
  EXPECT_EQ(summary["num_images"], 11);
  EXPECT_EQ(summary["has_ground_truth"], false);
  EXPECT_EQ(summary["has_capture_poses"], true);
  EXPECT_EQ(summary["num_capture_poses"], 11);
  EXPECT_EQ(summary["num_poses_without_image"], 20);
  EXPECT_EQ(summary["has_timestamps"], true);
  const Hdf5Reader reader(dir / "dataset.h5");
  EXPECT_EQ(reader.PoseSetNames(), std::vector<std::string>{"capture"});
  PoseRole role = PoseRole::kRefined;
  EXPECT_EQ(reader.ReadPoseSet("capture", &role).size(), 11u);
  EXPECT_EQ(role, PoseRole::kPrior);
}

// A dataset file with the sample's images and, optionally, capture poses.
std::string WriteDatasetFile(const TempDir& dir, const PoseSet* capture) {
  const fixtures::Capture sample = fixtures::SampleCapture();
  ImageSet images;
  images.image_root = dir.path().string();
  CameraIntrinsics camera;
  camera.width = sample.width;
  camera.height = sample.height;
  camera.params = {700, 700, 384, 256, 0, 0, 0, 0};
  images.cameras = {camera};
  for (int i = 0; i < 3; ++i) {
    images.images.push_back({std::to_string(i) + ".jpg", sample.width, sample.height, 0});
  }
  const std::string path = dir / "inputs.h5";
  Hdf5Writer writer(path);
  writer.WriteImages(images);
  if (capture)
    writer.WritePoseSet("capture", *capture, PoseRole::kPrior, Provenance{"test", {}, "", ""});
  writer.Commit();
  return path;
}

TEST(CaptureStages, PriorFromTheCaptureReportsMissingPosesAndFrames) {
  TempDir dir("prior_capture");
  PoseSet capture;
  capture.world_from_cam["0.jpg"] = Rigid3();
  capture.world_from_cam["1.jpg"] = Rigid3();
  capture.world_from_cam["7.jpg"] = Rigid3();  // no such image
  const std::string inputs = WriteDatasetFile(dir, &capture);
  const nlohmann::json summary =
      RunStage("prior", "{source: capture}", dir, {{"images", inputs}, {"poses/capture", inputs}});
  EXPECT_EQ(summary["num_poses"], 2);
  std::set<std::string> codes;
  for (const auto& warning : summary["warnings"]) codes.insert(warning["code"]);
  EXPECT_EQ(codes, (std::set<std::string>{"missing_frames", "missing_prior"}));
  EXPECT_EQ(Hdf5Reader(dir / "prior.h5").ReadPoseSet("prior").size(), 2u);
  EXPECT_THROW(RunStage("prior", "{source: capture, strict: true}", dir,
                        {{"images", inputs}, {"poses/capture", inputs}}),
               InputError);
}

TEST(CaptureStages, PriorSourcesNeedingWhatTheDatasetLacksAreClearErrors) {
  TempDir dir("prior_errors");
  const std::string inputs = WriteDatasetFile(dir, nullptr);
  const auto message = [&](const std::string& options) {
    try {
      RunStage("prior", options, dir, {{"images", inputs}});
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string perturb = message("{source: perturb}");
  EXPECT_NE(perturb.find("perturb needs ground truth; this dataset has none"), std::string::npos)
      << perturb;
  EXPECT_NE(perturb.find("use source: capture"), std::string::npos) << perturb;
  const std::string capture = message("{source: capture}");
  EXPECT_NE(capture.find("this dataset has no capture poses"), std::string::npos) << capture;
  EXPECT_NE(capture.find("record3d"), std::string::npos) << capture;
}

}  // namespace
}  // namespace raytime
