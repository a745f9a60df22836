// Issue 11's must-show for the trainer-ready export, against the real COLMAP 3.8: the sample scene
// with synthetic OpenCV distortion (known k1, k2, p1, p2) added to its images runs through
// raytime (front end, 4° prior, refine, export formats colmap_text + 3dgs); then
//   - `colmap image_undistorter` on the same distorted model (the refined poses as an OPENCV
//     COLMAP model) gives the same PINHOLE camera (width, height, fx, fy, cx, cy) and images
//     within a mean absolute difference per pixel and channel (the two warps differ: COLMAP
//     resamples at the distorted size and rescales, OpenCV's remap goes straight to the new size
//     with 1/32 px positions);
//   - `colmap model_analyzer` reads the exported model;
//   - the exported points3D reproject onto their observations (median) within the refine stage's
//     own residuals at the solution;
//   - the prior, refined and ground-truth folders hold the same images and split.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "core/statistics.h"
#include "formats/colmap_model.h"
#include "formats/dataset.h"
#include "tests/colmap_command.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// A phone-like lens: mild barrel with a little decentring (about 13 px at the corners of the
// 768 x 512 sample).
constexpr double kLensK1 = -0.08, kLensK2 = 0.03, kLensP1 = 6e-4, kLensP2 = -4e-4;
// Mean absolute difference per pixel and channel (of 255) between raytime's and COLMAP's
// undistorted images. Measured (issue 11's closing note): 0.95 over the 11 images, worst 1.08.
// Almost all of it is COLMAP's second resampling: image_undistorter warps at the distorted size
// (768 x 512) and then rescales to the new one (783 x 516) with FreeImage's bilinear filter, a
// slight blur; emulating that step brings the difference to 0.25, while OpenCV's remap (1/32 px
// positions) differs from an exact bilinear warp by only 0.11. Blurring both images (Gaussian,
// sigma 1 px) removes the kernels' difference and leaves the geometry: 0.36, where shifting
// raytime's image by a quarter pixel makes it 0.7-0.9. Bounds with room for other OpenCV builds:
constexpr double kMaxMeanAbsoluteDifference = 1.5;
constexpr double kMaxBlurredMeanAbsoluteDifference = 0.5;
constexpr double kMaxMeanSignedDifference = 0.1;

// The sample scene as a COLMAP dataset whose camera has the distortion above: each image resampled
// so that a pixel shows what the sample's pinhole camera sees along the distorted camera's ray
// (PNG, so both undistorters read the same pixels), and an OPENCV model with the ground truth.
void WriteDistortedSample(const fs::path& root) {
  DatasetOptions options;
  options.format = "strecha";
  options.root = std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11";
  const Dataset sample = LoadDataset(options);
  ASSERT_EQ(sample.images.cameras.size(), 1u);
  const CameraIntrinsics pinhole = sample.images.cameras[0];
  CameraIntrinsics distorted = pinhole;
  distorted.params[kK1] = kLensK1;
  distorted.params[kK2] = kLensK2;
  distorted.params[kP1] = kLensP1;
  distorted.params[kP2] = kLensP2;
  cv::Mat map_x(pinhole.height, pinhole.width, CV_32FC1),
      map_y(pinhole.height, pinhole.width, CV_32FC1);
  for (int y = 0; y < pinhole.height; ++y) {
    for (int x = 0; x < pinhole.width; ++x) {
      const double pixel[2] = {double(x), double(y)};
      double undistorted[2];
      UndistortPixel(distorted.params.data(), pixel, undistorted, 30);
      map_x.at<float>(y, x) = static_cast<float>(undistorted[0]);
      map_y.at<float>(y, x) = static_cast<float>(undistorted[1]);
    }
  }
  ImageSet images;
  images.cameras = {distorted};
  PoseSet ground_truth;
  fs::create_directories(root / "images");
  for (const ImageInfo& info : sample.images.images) {
    const cv::Mat original =
        cv::imread((fs::path(sample.images.image_root) / info.name).string(), cv::IMREAD_COLOR);
    cv::Mat out;
    cv::remap(original, out, map_x, map_y, cv::INTER_CUBIC, cv::BORDER_CONSTANT);
    const std::string name = fs::path(info.name).replace_extension(".png").string();
    ASSERT_TRUE(cv::imwrite((root / "images" / name).string(), out));
    images.images.push_back({name, info.width, info.height, 0});
    ground_truth.world_from_cam[name] = sample.ground_truth->world_from_cam.at(info.name);
  }
  WriteColmapModelText(ToColmapModel(images, ground_truth), (root / "sparse/0").string());
}

nlohmann::json ReadJson(const fs::path& path) {
  return nlohmann::json::parse(ReadTextFile(path.string()));
}

// Mean absolute difference per pixel and channel (0-255) of two images of one size.
double MeanAbsoluteDifference(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat difference;
  cv::absdiff(a, b, difference);
  const cv::Scalar sum = cv::sum(difference);
  return (sum[0] + sum[1] + sum[2] + sum[3]) / (double(a.total()) * a.channels());
}

TEST(TrainerExportColmapTest, SampleWithDistortionAgreesWithColmapAndReprojects) {
  const std::string colmap = FindOnPath("colmap");
  ASSERT_FALSE(colmap.empty())
      << "the COLMAP 3.8 binary `colmap` is not on PATH; this test needs it (CI installs it)";
  TempDir dir("trainer_export_colmap");
  const fs::path dataset = dir.path() / "distorted";
  WriteDistortedSample(dataset);
  if (HasFatalFailure()) return;

  // The demo's job on the distorted scene, exporting three pose sets for trainers, undistorted as
  // COLMAP does (no centring of the principal point, which image_undistorter does not do).
  const fs::path workdir = dir.path() / "work";
  const std::string pipeline = dir / "pipeline.yaml";
  WriteTextFileAtomically(
      pipeline,
      "name: distorted-sample\n"
      "dataset: {format: colmap, root: " +
          dataset.string() +
          "}\n"
          "stages:\n"
          "  - features: {max_features: 8192, first_octave: -1}\n"
          "  - matches: {pairs: exhaustive, guided_matching: true}\n"
          "  - prior: {source: perturb, mode: iid, level_deg: 4, seed: 0, "
          "translation_per_deg: 0.0125}\n"
          "  - refine: {preset: basin}\n"
          "  - export: {poses: [prior, refined, ground_truth], formats: [colmap_text, "
          "3dgs], centre_principal_point: false}\n");
  const CommandResult run =
      RunRaytime("run " + CommandLine({pipeline, "--workdir", workdir.string()}));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json summary = ReadJson(workdir / "summary.json");
  nlohmann::json refine, exported;
  for (const auto& stage : summary["stages"]) {
    if (stage["id"] == "refine") refine = stage["summary"];
    if (stage["id"] == "export") exported = stage["summary"]["3dgs"];
  }
  ASSERT_FALSE(exported.is_null()) << summary.dump(2);
  EXPECT_EQ(exported["num_images"], 11);
  EXPECT_EQ(exported["num_images_undistorted"], 11);
  EXPECT_EQ(exported["num_test"], 2);
  EXPECT_EQ(exported["points_from"], "refined");
  std::printf("3dgs export of 3 pose sets (11 images undistorted once): %.2f s\n",
              exported["seconds"].get<double>());

  // colmap image_undistorter on the refined poses with the distorted camera (the colmap_text
  // export: an OPENCV model), default options (blank_pixels 0, min_scale 0.2, max_scale 2).
  const fs::path by_colmap = dir.path() / "colmap_undistorted";
  ASSERT_TRUE(RunColmap(colmap,
                        {"image_undistorter", "--image_path", (dataset / "images").string(),
                         "--input_path", (workdir / "refined").string(), "--output_path",
                         by_colmap.string(), "--output_type", "COLMAP"},
                        dir / "image_undistorter.log")
                  .Succeeded())
      << ReadTextFile(dir / "image_undistorter.log");
  const fs::path ours = workdir / "3dgs" / "refined";
  const ColmapModel theirs_model = ReadColmapModelBinary((by_colmap / "sparse").string());
  const ColmapModel ours_model = ReadColmapModelBinary((ours / "sparse/0").string());
  ASSERT_EQ(theirs_model.cameras.size(), 1u);
  ASSERT_EQ(ours_model.cameras.size(), 1u);
  const ColmapCamera& theirs_camera = theirs_model.cameras.begin()->second;
  const ColmapCamera& ours_camera = ours_model.cameras.begin()->second;
  EXPECT_EQ(ours_camera.model, "PINHOLE");
  EXPECT_EQ(theirs_camera.model, "PINHOLE");
  EXPECT_EQ(ours_camera.width, theirs_camera.width);
  EXPECT_EQ(ours_camera.height, theirs_camera.height);
  ASSERT_EQ(ours_camera.params.size(), 4u);
  ASSERT_EQ(theirs_camera.params.size(), 4u);
  double camera_difference = 0.0;
  for (int k = 0; k < 4; ++k) {
    camera_difference =
        std::max(camera_difference, std::abs(ours_camera.params[k] - theirs_camera.params[k]));
  }
  EXPECT_LT(camera_difference, 1e-9);
  std::printf(
      "undistorted camera: raytime %llu x %llu fx %.6f fy %.6f cx %.6f cy %.6f; colmap %llu x "
      "%llu, largest parameter difference %.3g px (distorted 768 x 512)\n",
      (unsigned long long)ours_camera.width, (unsigned long long)ours_camera.height,
      ours_camera.params[0], ours_camera.params[1], ours_camera.params[2], ours_camera.params[3],
      (unsigned long long)theirs_camera.width, (unsigned long long)theirs_camera.height,
      camera_difference);

  double sum = 0.0, worst = 0.0, interior_sum = 0.0, blurred_sum = 0.0, blurred_worst = 0.0;
  int count = 0;
  for (const auto& [id, image] : ours_model.images) {
    const cv::Mat a = cv::imread((ours / "images" / image.name).string(), cv::IMREAD_UNCHANGED);
    const cv::Mat b =
        cv::imread((by_colmap / "images" / image.name).string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(a.empty()) << image.name;
    ASSERT_FALSE(b.empty()) << image.name;
    ASSERT_EQ(a.size(), b.size()) << image.name;
    ASSERT_EQ(a.type(), b.type()) << image.name;
    const double mad = MeanAbsoluteDifference(a, b);
    // Without a 2-pixel frame, where the warps treat the image border differently.
    const cv::Rect inside(2, 2, a.cols - 4, a.rows - 4);
    interior_sum += MeanAbsoluteDifference(a(inside), b(inside));
    sum += mad;
    worst = std::max(worst, mad);
    cv::Mat a_blurred, b_blurred;
    cv::GaussianBlur(a, a_blurred, cv::Size(0, 0), 1.0);
    cv::GaussianBlur(b, b_blurred, cv::Size(0, 0), 1.0);
    const double blurred = MeanAbsoluteDifference(a_blurred, b_blurred);
    blurred_sum += blurred;
    blurred_worst = std::max(blurred_worst, blurred);
    const cv::Scalar mean_a = cv::mean(a), mean_b = cv::mean(b);
    EXPECT_LT(
        std::abs((mean_a[0] + mean_a[1] + mean_a[2]) - (mean_b[0] + mean_b[1] + mean_b[2])) / 3.0,
        kMaxMeanSignedDifference)
        << image.name;
    ++count;
  }
  ASSERT_EQ(count, 11);
  std::printf(
      "undistorted images vs colmap image_undistorter: mean absolute difference %.3f (worst image "
      "%.3f, without a 2 px frame %.3f) of 255; both blurred (sigma 1 px) %.3f (worst %.3f)\n",
      sum / count, worst, interior_sum / count, blurred_sum / count, blurred_worst);
  EXPECT_LT(worst, kMaxMeanAbsoluteDifference);
  EXPECT_LT(blurred_worst, kMaxBlurredMeanAbsoluteDifference);

  // colmap model_analyzer reads the export.
  const std::string analyzer_log = dir / "model_analyzer.log";
  ASSERT_TRUE(
      RunColmap(colmap, {"model_analyzer", "--path", (ours / "sparse/0").string()}, analyzer_log)
          .Succeeded())
      << ReadTextFile(analyzer_log);
  const std::string analysis = ReadTextFile(analyzer_log);
  EXPECT_NE(analysis.find("Points: " + std::to_string(ours_model.points3D.size())),
            std::string::npos)
      << analysis;
  EXPECT_NE(analysis.find("Registered images: 11"), std::string::npos) << analysis;
  std::printf("colmap model_analyzer:\n%s\n", analysis.c_str());

  // The points reproject onto their observations within the solve's own residuals.
  ASSERT_GT(ours_model.points3D.size(), 1000u);
  std::vector<double> errors;
  for (const auto& [id, image] : ours_model.images) {
    const ColmapCamera& camera = ours_model.cameras.at(image.camera_id);
    for (size_t k = 0; k < image.points2D.size(); ++k) {
      const Eigen::Vector3d p =
          image.cam_from_world.rotation * ours_model.points3D.at(image.point3D_ids[k]).xyz +
          image.cam_from_world.translation;
      ASSERT_GT(p.z(), 0);
      const Eigen::Vector2d projected(camera.params[0] * p.x() / p.z() + camera.params[2],
                                      camera.params[1] * p.y() / p.z() + camera.params[3]);
      errors.push_back((projected - image.points2D[k]).norm());
    }
  }
  const double median = Median(errors, 0.0);
  std::sort(errors.begin(), errors.end());
  const double p90 = errors[errors.size() * 9 / 10];
  const double refine_median = refine["passes"].back()["residual_median_px"].get<double>();
  const double refine_p90 = refine["passes"].back()["residual_p90_px"].get<double>();
  std::printf(
      "exported points3D: %zu points, %zu observations, reprojection median %.3f px, 90th "
      "percentile %.3f px; refine residuals at the solution: median %.3f px, 90th percentile "
      "%.3f px; ground truth / prior folders (Sim(3) of the centres): median %.3f / %.3f px\n",
      ours_model.points3D.size(), errors.size(), median, p90, refine_median, refine_p90,
      exported["reprojection_median_px"]["ground_truth"].get<double>(),
      exported["reprojection_median_px"]["prior"].get<double>());
  EXPECT_LE(median, refine_median);
  EXPECT_LE(p90, refine_p90);
  EXPECT_NEAR(median, exported["reprojection_median_px"]["refined"].get<double>(), 1e-6);

  // The three pose sets' folders: same images (bytes), same split; only the poses differ.
  for (const char* set : {"prior", "ground_truth"}) {
    const fs::path other = workdir / "3dgs" / set;
    EXPECT_EQ(ReadTextFile((other / "test.txt").string()),
              ReadTextFile((ours / "test.txt").string()));
    EXPECT_EQ(ReadTextFile((other / "test.txt").string()), "0000.png\n0008.png\n");
    const ColmapModel model = ReadColmapModelBinary((other / "sparse/0").string());
    EXPECT_EQ(model.cameras.begin()->second.params, ours_camera.params);
    for (const auto& [id, image] : model.images) {
      EXPECT_EQ(image.name, ours_model.images.at(id).name);
      EXPECT_EQ(image.points2D, ours_model.images.at(id).points2D);
      EXPECT_EQ(ReadTextFile((other / "images" / image.name).string()),
                ReadTextFile((ours / "images" / image.name).string()));
    }
  }
}

}  // namespace
}  // namespace raytime
