// The trainer-ready 3DGS export's kernels (splat/undistortion.h, splat/trainer_export.h,
// issue 11): the undistorted camera against a case computed by hand, the resampled image against
// the analytic one, track merging (a chained match, a disagreeing chain, a point behind a camera),
// the every-8th split, and a whole export of a small synthetic scene (layout, identical images
// across pose sets, links between 2D points and 3D points, points in each set's frame).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/colmap_model.h"
#include "splat/trainer_export.h"
#include "splat/undistortion.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

CameraIntrinsics Camera(int width, int height, double f, double cx, double cy, double k1 = 0,
                        double k2 = 0, double p1 = 0, double p2 = 0) {
  CameraIntrinsics camera;
  camera.width = width;
  camera.height = height;
  camera.params = {f, f, cx, cy, k1, k2, p1, p2};
  return camera;
}

// Barrel distortion with k1 chosen so that a point 0.5 focal lengths from the axis, distorted,
// undistorts to exactly 0.52 (0.52 (1 + k1 0.52²) = 0.5): f = 200 px, principal point (100, 100)
// (OpenCV; 100.5 in COLMAP's convention), 211 x 211 pixels. The left border pixel of the
// principal row is 100 px = 0.5 focal lengths left of it, so undistorted it lies at COLMAP pixel
// 100.5 - 0.52 · 200 = -3.5, the border point closest to the centre (barrel moves the corners out
// most). The far border (110 px = 0.55 focal lengths right) undistorts to about 0.576 (ratio
// 0.955), so the near one decides: no blank pixel needs the factor 100.5 / 104, width =
// floor(211 · 104 / 100.5) = floor(218.35) = 218, and the principal point keeps its relative
// position: 100.5 · 218 / 211 in COLMAP's convention. The same for y.
// (COLMAP's camera: centre_principal_point off.)
TEST(UndistortionTest, CameraAsColmapComputesIt) {
  const double k1 = -(0.52 - 0.5) / std::pow(0.52, 3);
  const CameraIntrinsics distorted = Camera(211, 211, 200.0, 100.0, 100.0, k1);
  UndistortionOptions as_colmap;
  as_colmap.centre_principal_point = false;
  const CameraIntrinsics pinhole = UndistortedCamera(distorted, as_colmap);
  EXPECT_EQ(pinhole.width, 218);
  EXPECT_EQ(pinhole.height, 218);
  EXPECT_DOUBLE_EQ(pinhole.fx(), 200.0);
  EXPECT_DOUBLE_EQ(pinhole.fy(), 200.0);
  EXPECT_NEAR(pinhole.cx(), 100.5 * 218.0 / 211.0 - 0.5, 1e-12);
  EXPECT_NEAR(pinhole.cy(), 100.5 * 218.0 / 211.0 - 0.5, 1e-12);
  EXPECT_FALSE(pinhole.HasDistortion());

  // The scale is clipped to [min_scale, max_scale]: 1.01 · 211 = 213.11 -> 213.
  UndistortionOptions clipped = as_colmap;
  clipped.max_scale = 1.01;
  const CameraIntrinsics small = UndistortedCamera(distorted, clipped);
  EXPECT_EQ(small.width, 213);
  EXPECT_NEAR(small.cx(), 100.5 * 213.0 / 211.0 - 0.5, 1e-12);

  // Keeping every distorted pixel (blank_pixels = 1) needs a larger image still.
  UndistortionOptions keep_all = as_colmap;
  keep_all.blank_pixels = 1.0;
  EXPECT_GT(UndistortedCamera(distorted, keep_all).width, 218);

  // No distortion (COLMAP: |k| <= 1e-8): the camera as it is.
  const CameraIntrinsics plain = Camera(640, 480, 500.0, 319.5, 239.5, 1e-9);
  const CameraIntrinsics same = UndistortedCamera(plain, as_colmap);
  EXPECT_TRUE(IsUndistorted(plain));
  EXPECT_FALSE(IsResampled(plain, same));
  EXPECT_EQ(same.width, 640);
  EXPECT_EQ(same.height, 480);
  EXPECT_EQ(same.cx(), 319.5);
  EXPECT_FALSE(same.HasDistortion());

  // A lens so strong that the corners have no undistorted position (r - 0.128 r³ < sqrt(2)).
  EXPECT_THROW(
      UndistortedCamera(Camera(201, 201, 100.0, 100.0, 100.0, -0.128), UndistortionOptions()),
      InputError);

  UndistortionOptions invalid;
  invalid.min_scale = 3.0;
  EXPECT_THROW(UndistortedCamera(distorted, invalid), InputError);
}

// Centring (the default): the largest image centred on the principal point, which trainers that
// place it at the centre (Inria, OpenSplat on CPU) then read right. COLMAP convention: a principal
// point 7.5 px left of centre in a 640-wide image (cx 312.5 OpenCV = 313 COLMAP) leaves
// floor(2 · 313) = 626 columns, cx = 313 - 0.5; below centre in y (cy 250.25 OpenCV = 250.75):
// floor(2 · (480 - 250.75)) = 458 rows, cy = 229 - 0.5. The image is the photo shifted by
// (0, 250.25 - 228.5 = 21.75) px (bilinear: exact on a linear image up to remap's 1/32 px).
TEST(UndistortionTest, CentringCropsAboutThePrincipalPoint) {
  const CameraIntrinsics plain = Camera(640, 480, 500.0, 312.5, 250.25);
  const CameraIntrinsics centred = UndistortedCamera(plain, UndistortionOptions());
  EXPECT_EQ(centred.width, 626);
  EXPECT_EQ(centred.height, 458);
  EXPECT_DOUBLE_EQ(centred.cx(), 0.5 * 626 - 0.5);
  EXPECT_DOUBLE_EQ(centred.cy(), 0.5 * 458 - 0.5);
  EXPECT_DOUBLE_EQ(centred.fx(), 500.0);
  EXPECT_TRUE(IsResampled(plain, centred));
  cv::Mat image(480, 640, CV_32FC1);
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) image.at<float>(y, x) = static_cast<float>(x + 1000 * y);
  }
  const cv::Mat out = UndistortImage(image, plain, centred);
  ASSERT_EQ(out.cols, 626);
  ASSERT_EQ(out.rows, 458);
  for (const auto& [x, y] : std::vector<std::pair<int, int>>{{0, 0}, {625, 457}, {300, 200}}) {
    EXPECT_NEAR(out.at<float>(y, x), x + 1000 * (y + 21.75), 1000 * 1.0 / 32 + 1e-3)
        << x << "," << y;
  }
  // A principal point already centred: the camera as it is, the image copied.
  const CameraIntrinsics centre = Camera(640, 480, 500.0, 319.5, 239.5);
  EXPECT_FALSE(IsResampled(centre, UndistortedCamera(centre, UndistortionOptions())));
  // With distortion: the resized camera, then centred.
  const CameraIntrinsics distorted = Camera(320, 240, 300.0, 161.3, 118.2, -0.2, 0.05);
  const CameraIntrinsics pinhole = UndistortedCamera(distorted, UndistortionOptions());
  EXPECT_DOUBLE_EQ(pinhole.cx(), 0.5 * pinhole.width - 0.5);
  EXPECT_DOUBLE_EQ(pinhole.cy(), 0.5 * pinhole.height - 0.5);
}

// Each undistorted pixel holds the distorted image at where the distorted camera sees its ray:
// on an image linear in x and y (which bilinear interpolation reproduces) that is the linear
// function at the distorted position, up to OpenCV's 1/32 px position quantization in remap.
TEST(UndistortionTest, ImageIsResampledAlongTheRays) {
  const CameraIntrinsics distorted =
      Camera(320, 240, 300.0, 161.3, 118.2, -0.2, 0.05, 0.002, -0.001);
  const CameraIntrinsics pinhole = UndistortedCamera(distorted, UndistortionOptions());
  cv::Mat image(240, 320, CV_32FC1);
  const auto value = [](double x, double y) { return 20.0 + 0.5 * x + 0.25 * y; };
  for (int y = 0; y < 240; ++y) {
    for (int x = 0; x < 320; ++x) image.at<float>(y, x) = static_cast<float>(value(x, y));
  }
  const cv::Mat out = UndistortImage(image, distorted, pinhole);
  ASSERT_EQ(out.cols, pinhole.width);
  ASSERT_EQ(out.rows, pinhole.height);
  double worst = 0.0;
  int checked = 0;
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      const double u[2] = {double(x), double(y)};
      // The pinhole pixel's ray, distorted into the original image.
      const double normalized[2] = {(u[0] - pinhole.cx()) / pinhole.fx(),
                                    (u[1] - pinhole.cy()) / pinhole.fy()};
      double xd[2];
      DistortNormalized(distorted.params.data(), normalized, xd);
      const double sx = distorted.fx() * xd[0] + distorted.cx();
      const double sy = distorted.fy() * xd[1] + distorted.cy();
      if (sx < 0 || sy < 0 || sx > 319 || sy > 239) continue;
      worst = std::max(worst, std::abs(out.at<float>(y, x) - value(sx, sy)));
      ++checked;
    }
  }
  EXPECT_GT(checked, out.rows * out.cols * 9 / 10);  // blank_pixels = 0: nearly every pixel
  EXPECT_LT(worst, 0.75 / 32 + 1e-3);

  // Keypoints move with the image: a pinhole pixel, distorted, comes back.
  const Eigen::Vector2d keypoint(12.25, 200.5);
  double undistorted[2];
  UndistortPixel(distorted.params.data(), keypoint.data(), undistorted, 30);
  const Eigen::Vector2d mapped = UndistortedPixel(distorted, pinhole, keypoint);
  EXPECT_NEAR(mapped.x(), (undistorted[0] - distorted.cx()) + pinhole.cx(), 1e-9);
  EXPECT_NEAR(mapped.y(), (undistorted[1] - distorted.cy()) + pinhole.cy(), 1e-9);

  EXPECT_THROW(UndistortImage(cv::Mat(10, 10, CV_8UC3), distorted, pinhole), InputError);
}

TEST(TrainerExportTest, SplitHoldsOutEveryEighthImageByName) {
  std::vector<std::string> names;
  for (int i = 16; i >= 0; --i) names.push_back(std::to_string(100 + i) + ".jpg");
  const TrainTestSplit split = SplitEveryNth(names, 8);
  EXPECT_EQ(split.test, (std::vector<std::string>{"100.jpg", "108.jpg", "116.jpg"}));
  ASSERT_EQ(split.train.size(), 14u);
  EXPECT_EQ(split.train.front(), "101.jpg");
  EXPECT_EQ(split.train.back(), "115.jpg");
  EXPECT_TRUE(std::is_sorted(split.train.begin(), split.train.end()));
  // Sorted by name, not by number: "10.jpg" < "9.jpg".
  EXPECT_EQ(SplitEveryNth({"9.jpg", "10.jpg", "11.jpg"}, 2).test,
            (std::vector<std::string>{"10.jpg", "9.jpg"}));
}

// Three cameras at x = -1, 0, 1 looking down +z (identity rotation), f = 100, c = (50, 50).
std::vector<Eigen::Matrix<double, 3, 4>> ThreeCameras() {
  std::vector<Eigen::Matrix<double, 3, 4>> projections;
  for (int i = 0; i < 3; ++i) {
    Eigen::Matrix3d K;
    K << 100, 0, 50, 0, 100, 50, 0, 0, 1;
    Eigen::Matrix<double, 3, 4> Rt;
    Rt << 1, 0, 0, -(i - 1.0), 0, 1, 0, 0, 0, 0, 1, 0;
    projections.push_back(K * Rt);
  }
  return projections;
}

Eigen::Vector2d Pixel(int camera, const Eigen::Vector3d& x) {
  return Eigen::Vector2d(100 * (x.x() - (camera - 1.0)) / x.z() + 50, 100 * x.y() / x.z() + 50);
}

// The copies of a keypoint SIFT describes twice (two orientations), matched alike, are two tracks
// at bitwise the same point: one point in the export (OpenSplat made a Gaussian of NaNs of such a
// twin), with both tracks' observations, colours averaged by them.
TEST(TrainerExportTest, TracksAtTheSamePointAreOne) {
  const std::vector<Eigen::Matrix<double, 3, 4>> projections = ThreeCameras();
  const Eigen::Vector3d E(0.2, 0.1, 5.0), F(-0.3, 0.2, 4.0);
  TrackObservations obs;
  obs.image.resize(7);
  obs.points.resize(7, 3);
  obs.pixels.resize(7, 2);
  obs.colours.resize(7, 3);
  const int images[7] = {0, 1, 0, 1, 2, 0, 2};
  const Eigen::Vector3d points[7] = {E, E, E, E, E, F, F};
  for (int o = 0; o < 7; ++o) {
    obs.image(o) = images[o];
    obs.points.row(o) = points[o].transpose();
    obs.pixels.row(o) = Pixel(images[o], points[o]).transpose();
    obs.colours.row(o) = Eigen::RowVector3d::Constant(o < 2 ? 30.0 : 60.0);
  }
  obs.matches.resize(4, 2);
  obs.matches << 0, 1, 2, 3, 3, 4, 5, 6;  // E twice (the second seen thrice), F once
  TrackMergeSummary summary;
  const std::vector<MergedTrack> tracks = MergeTracks(obs, projections, 4.0, &summary);
  ASSERT_EQ(tracks.size(), 2u);
  EXPECT_EQ(tracks[0].observations, (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_EQ(tracks[0].xyz, E);
  EXPECT_LT((tracks[0].rgb - Eigen::Vector3d::Constant((2 * 30.0 + 3 * 60.0) / 5)).norm(), 1e-12);
  EXPECT_EQ(tracks[1].observations, (std::vector<int>{5, 6}));
  EXPECT_EQ(summary.num_tracks, 3);
  EXPECT_EQ(summary.num_kept, 2);
  EXPECT_EQ(summary.num_duplicates_merged, 1);
  EXPECT_EQ(summary.num_observations_kept, 7);
}

TEST(TrainerExportTest, ChainedMatchesMergeIntoOneTrack) {
  const std::vector<Eigen::Matrix<double, 3, 4>> projections = ThreeCameras();
  const Eigen::Vector3d A(0.2, 0.1, 5.0), B(-0.3, 0.2, 4.0), C(0.1, -0.2, 6.0), D(0, 0, -3.0);
  struct Row {
    int image;
    Eigen::Vector3d point;  // NaN: no ray time
    Eigen::Vector2d pixel;
    Eigen::Vector3d colour;
  };
  const Eigen::Vector3d none = Eigen::Vector3d::Constant(std::nan(""));
  const Eigen::Vector3d off(0.01, -0.02, 0.03);  // each ray point a little off the scene point
  std::vector<Row> rows = {
      // Track A: 0-1 and 1-2 chain into one track of three observations.
      {0, A + off, Pixel(0, A), {10, 20, 30}},
      {1, A - off, Pixel(1, A), {20, 30, 40}},
      {2, A, Pixel(2, A), {30, 40, 50}},
      // Track B-C: a wrong match joins two scene points: no point explains both.
      {0, B, Pixel(0, B), {0, 0, 0}},
      {1, C, Pixel(1, C), {0, 0, 0}},
      // Track D: behind the cameras.
      {0, D, Eigen::Vector2d(50, 50), {0, 0, 0}},
      {2, D, Eigen::Vector2d(50, 50), {0, 0, 0}},
      // Track without ray times (anchored non-anchors only).
      {1, none, Pixel(1, C), {0, 0, 0}},
      {2, none, Pixel(2, C), {0, 0, 0}},
      // An observation no match reaches.
      {2, B, Pixel(2, B), {0, 0, 0}},
  };
  TrackObservations obs;
  const int n = static_cast<int>(rows.size());
  obs.image.resize(n);
  obs.points.resize(n, 3);
  obs.pixels.resize(n, 2);
  obs.colours.resize(n, 3);
  for (int o = 0; o < n; ++o) {
    obs.image(o) = rows[o].image;
    obs.points.row(o) = rows[o].point.transpose();
    obs.pixels.row(o) = rows[o].pixel.transpose();
    obs.colours.row(o) = rows[o].colour.transpose();
  }
  obs.matches.resize(5, 2);
  obs.matches << 1, 2, 0, 1, 3, 4, 5, 6, 7, 8;
  TrackMergeSummary summary;
  const std::vector<MergedTrack> tracks = MergeTracks(obs, projections, 4.0, &summary);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].observations, (std::vector<int>{0, 1, 2}));
  EXPECT_LT((tracks[0].xyz - A).norm(), 1e-12);  // the per-coordinate median
  EXPECT_LT((tracks[0].rgb - Eigen::Vector3d(20, 30, 40)).norm(), 1e-12);
  EXPECT_LT(tracks[0].mean_error_px, 1e-9);
  EXPECT_EQ(summary.num_tracks, 4);
  EXPECT_EQ(summary.num_kept, 1);
  EXPECT_EQ(summary.num_disagreeing, 1);
  EXPECT_EQ(summary.num_behind_camera, 1);
  EXPECT_EQ(summary.num_without_ray_time, 1);
  EXPECT_EQ(summary.num_observations_kept, 3);

  // With a threshold the B-C chain's own disagreement passes, its point is kept.
  EXPECT_EQ(MergeTracks(obs, projections, 1e6, &summary).size(), 2u);
}

// A small scene for ExportForTrainers: four 96 x 72 images (camera 0 distorted, camera 1 not),
// points seen by all, their ray times, matches chaining consecutive images.
struct SmallScene {
  ImageSet images;
  PoseSet refined;
  RayTimeObservations rays;
  std::vector<Eigen::Vector3d> points;
};

SmallScene MakeSmallScene(const fs::path& image_root) {
  SmallScene scene;
  scene.images.image_root = image_root.string();
  scene.images.cameras = {Camera(96, 72, 80.0, 47.3, 35.6, -0.15, 0.02, 0.001, -0.002),
                          Camera(96, 72, 82.0, 47.5, 35.5)};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 12; ++i) {
    const double z = 5 + u(rng);
    const double y = 0.6 * u(rng);
    scene.points.emplace_back(0.8 * u(rng), y, z);
  }
  fs::create_directories(image_root);
  const int num_images = 4;
  for (int i = 0; i < num_images; ++i) {
    // Names out of order on purpose: ids and the split follow name order.
    const std::string name = "img" + std::to_string((i * 3) % num_images) + ".png";
    const int camera = i == 2 ? 1 : 0;
    scene.images.images.push_back({name, 96, 72, camera});
    cv::Mat pixels(72, 96, CV_8UC3);
    cv::randu(pixels, cv::Scalar::all(0), cv::Scalar::all(255));
    cv::imwrite((image_root / name).string(), pixels);
    const Rigid3 pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitY())),
                      Eigen::Vector3d(0.3 * i, 0.05 * i * i, 0.1 * (i % 2)));
    scene.refined.world_from_cam[name] = pose;
    scene.rays.image_names.push_back(name);
  }
  std::sort(scene.images.images.begin(), scene.images.images.end(),
            [](const ImageInfo& a, const ImageInfo& b) { return a.name < b.name; });
  std::vector<std::array<int, 2>> observations;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<double> ray_times;
  for (size_t p = 0; p < scene.points.size(); ++p) {
    for (int r = 0; r < num_images; ++r) {
      const std::string& name = scene.rays.image_names[r];
      const ImageInfo& info = scene.images.images[scene.images.Find(name)];
      const CameraIntrinsics& camera = scene.images.cameras[info.camera_index];
      const Rigid3& pose = scene.refined.world_from_cam.at(name);
      const Eigen::Vector3d in_cam = pose.rotation.inverse() * (scene.points[p] - pose.translation);
      const double undistorted[2] = {camera.fx() * in_cam.x() / in_cam.z() + camera.cx(),
                                     camera.fy() * in_cam.y() / in_cam.z() + camera.cy()};
      Eigen::Vector2d distorted;
      DistortPixel(camera.params.data(), undistorted, distorted.data());
      observations.push_back({r, static_cast<int>(p)});
      pixels.push_back(distorted);
      ray_times.push_back(in_cam.norm());
    }
  }
  const auto n = static_cast<Eigen::Index>(observations.size());
  scene.rays.observations.resize(n, 2);
  scene.rays.pixels.resize(n, 2);
  scene.rays.ray_times.resize(n);
  for (Eigen::Index o = 0; o < n; ++o) {
    scene.rays.observations.row(o) << observations[o][0], observations[o][1];
    scene.rays.pixels.row(o) = pixels[o].transpose();
    scene.rays.ray_times(o) = ray_times[o];
  }
  // Point p's observations are rows 4p .. 4p + 3: chain them.
  scene.rays.matches.resize(static_cast<Eigen::Index>(scene.points.size()) * 3, 2);
  for (Eigen::Index p = 0; p < static_cast<Eigen::Index>(scene.points.size()); ++p) {
    for (int k = 0; k < 3; ++k) scene.rays.matches.row(3 * p + k) << 4 * p + k, 4 * p + k + 1;
  }
  return scene;
}

TEST(TrainerExportTest, ExportsEveryPoseSetWithTheSameImagesSplitAndTracks) {
  TempDir dir("trainer_export");
  const SmallScene scene = MakeSmallScene(dir.path() / "dataset");
  // "ground_truth": the refined poses in another frame (scale 2, rotated, moved).
  Sim3 similarity;
  similarity.scale = 2.0;
  similarity.rotation = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized());
  similarity.translation = Eigen::Vector3d(1, -2, 3);
  PoseSet ground_truth;
  for (const auto& [name, pose] : scene.refined.world_from_cam) {
    ground_truth.world_from_cam[name] = similarity.TransformPose(pose);
  }
  const std::map<std::string, PoseSet> poses = {{"refined", scene.refined},
                                                {"ground_truth", ground_truth}};
  const RayTimeSource source{"refined", scene.refined, scene.rays};
  TrainerExportOptions options;
  options.test_every = 3;
  Warnings warnings;
  const std::string root = dir / "3dgs";
  const TrainerExportSummary summary =
      ExportForTrainers(scene.images, poses, source, options, root, &warnings);
  EXPECT_TRUE(warnings.empty());
  EXPECT_EQ(summary.num_images, 4);
  EXPECT_EQ(summary.num_images_undistorted, 3);
  EXPECT_EQ(summary.num_images_copied, 1);
  EXPECT_EQ(summary.num_test, 2);  // img0, img3
  EXPECT_EQ(summary.num_points, 12);
  EXPECT_EQ(summary.tracks.num_kept, 12);
  EXPECT_EQ(summary.points_frame.at("refined"), "solve");
  EXPECT_EQ(summary.points_frame.at("ground_truth"), "sim3");
  EXPECT_LT(summary.reprojection_median_px.at("refined"), 1e-6);
  EXPECT_LT(summary.reprojection_median_px.at("ground_truth"), 1e-6);
  ASSERT_EQ(summary.undistortion_scale_x.size(), 2u);

  std::set<std::string> leftovers;
  for (const auto& entry : fs::directory_iterator(root)) {
    leftovers.insert(entry.path().filename().string());
  }
  EXPECT_EQ(leftovers, (std::set<std::string>{"ground_truth", "refined"}));

  for (const std::string set : {"refined", "ground_truth"}) {
    SCOPED_TRACE(set);
    const fs::path out = fs::path(root) / set;
    for (const char* file : {"sparse/0/cameras.bin", "sparse/0/images.bin", "sparse/0/points3D.bin",
                             "sparse/0/cameras.txt", "sparse/0/images.txt", "sparse/0/points3D.txt",
                             "transforms.json", "sparse_pc.ply", "test.txt", "train.txt"}) {
      EXPECT_TRUE(fs::is_regular_file(out / file)) << file;
    }
    EXPECT_EQ(ReadTextFile((out / "test.txt").string()), "img0.png\nimg3.png\n");
    EXPECT_EQ(ReadTextFile((out / "train.txt").string()), "img1.png\nimg2.png\n");
    for (const ImageInfo& info : scene.images.images) {
      EXPECT_EQ(ReadTextFile((out / "images" / info.name).string()),
                ReadTextFile((fs::path(root) / "refined" / "images" / info.name).string()));
    }
    // The undistortion-free camera's image is the original file.
    EXPECT_EQ(ReadTextFile((out / "images" / "img2.png").string()),
              ReadTextFile((dir.path() / "dataset" / "img2.png").string()));

    const ColmapModel text = ReadColmapModelText((out / "sparse/0").string());
    const ColmapModel model = ReadColmapModelBinary((out / "sparse/0").string());
    ASSERT_EQ(model.cameras.size(), 2u);
    for (const auto& [id, camera] : model.cameras) EXPECT_EQ(camera.model, "PINHOLE");
    ASSERT_EQ(model.images.size(), 4u);
    EXPECT_EQ(model.images.at(1).name, "img0.png");
    EXPECT_EQ(text.points3D.size(), model.points3D.size());
    ASSERT_EQ(model.points3D.size(), 12u);
    // Every 2D point names a 3D point whose track names it back, and the point projects onto it.
    int links = 0;
    for (const auto& [image_id, image] : model.images) {
      const CameraIntrinsics camera = IntrinsicsFromColmap(model.cameras.at(image.camera_id));
      for (size_t k = 0; k < image.points2D.size(); ++k) {
        const ColmapPoint3D& point = model.points3D.at(image.point3D_ids[k]);
        bool named = false;
        for (const ColmapTrackElement& e : point.track) {
          named = named || (e.image_id == image_id && e.point2D_idx == k);
        }
        EXPECT_TRUE(named);
        const Eigen::Vector3d in_cam =
            image.cam_from_world.rotation * point.xyz + image.cam_from_world.translation;
        const Eigen::Vector2d projected(camera.fx() * in_cam.x() / in_cam.z() + camera.cx() + 0.5,
                                        camera.fy() * in_cam.y() / in_cam.z() + camera.cy() + 0.5);
        EXPECT_LT((projected - image.points2D[k]).norm(), 1e-6);
        ++links;
      }
    }
    EXPECT_EQ(links, 48);
    // The points are the scene's, in this set's frame.
    for (const auto& [id, point] : model.points3D) {
      const Eigen::Vector3d truth =
          set == "refined" ? scene.points[id - 1] : similarity * scene.points[id - 1];
      EXPECT_LT((point.xyz - truth).norm(), 1e-6);
    }

    const nlohmann::json transforms =
        nlohmann::json::parse(ReadTextFile((out / "transforms.json").string()));
    EXPECT_EQ(transforms["ply_file_path"], "sparse_pc.ply");
    EXPECT_EQ(transforms["test_filenames"],
              nlohmann::json::array({"images/img0.png", "images/img3.png"}));
    EXPECT_EQ(transforms["val_filenames"], transforms["test_filenames"]);
    EXPECT_EQ(transforms["train_filenames"],
              nlohmann::json::array({"images/img1.png", "images/img2.png"}));
    ASSERT_EQ(transforms["frames"].size(), 4u);
    EXPECT_EQ(transforms["frames"][0]["file_path"], "images/img0.png");
    EXPECT_EQ(transforms["frames"][0]["k1"], 0.0);
    // nerfstudio's own layout (float x y z, uchar colours): readers that take x, y, z as 4-byte
    // floats (OpenSplat) read back the points.
    const std::string ply = ReadTextFile((out / "sparse_pc.ply").string());
    const std::string header =
        "ply\nformat binary_little_endian 1.0\nelement vertex 12\nproperty float x\n"
        "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
        "property uchar blue\nend_header\n";
    ASSERT_EQ(ply.rfind(header, 0), 0u);
    ASSERT_EQ(ply.size(), header.size() + 12 * (3 * sizeof(float) + 3));
    ASSERT_EQ(model.points3D.size(), 12u);
    float first[3];
    std::memcpy(first, ply.data() + header.size(), sizeof(first));
    const Eigen::Vector3d xyz = model.points3D.begin()->second.xyz;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(first[k], xyz(k), 1e-5 * (1 + std::abs(xyz(k))));
  }

  // Without ray times: empty points3D, no PLY, and a warning.
  Warnings no_points;
  const TrainerExportSummary empty =
      ExportForTrainers(scene.images, poses, std::nullopt, options, dir / "3dgs_empty", &no_points);
  EXPECT_EQ(empty.num_points, 0);
  ASSERT_EQ(no_points.size(), 1u);
  EXPECT_EQ(no_points[0].code, "no_initial_points");
  EXPECT_FALSE(fs::exists(dir.path() / "3dgs_empty" / "refined" / "sparse_pc.ply"));
  EXPECT_TRUE(ReadColmapModel((dir.path() / "3dgs_empty" / "refined" / "sparse/0").string())
                  .points3D.empty());
}

TEST(TrainerExportTest, UnreadableImageIsAnInputErrorAndLeavesNothing) {
  TempDir dir("trainer_export");
  SmallScene scene = MakeSmallScene(dir.path() / "dataset");
  fs::remove(dir.path() / "dataset" / "img1.png");
  Warnings warnings;
  EXPECT_THROW(ExportForTrainers(scene.images, {{"refined", scene.refined}},
                                 RayTimeSource{"refined", scene.refined, scene.rays},
                                 TrainerExportOptions(), dir / "3dgs", &warnings),
               InputError);
  EXPECT_TRUE(fs::is_empty(dir.path() / "3dgs"));
}

}  // namespace
}  // namespace raytime
