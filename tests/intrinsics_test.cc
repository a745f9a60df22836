// Tolerance where it costs nothing (core/intrinsics.h, issue 13): DTU's negligible skew is dropped
// with a warning and a real one refused naming the file; per-view cameras that differ by float
// noise are one camera, cameras that really differ stay apart.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/intrinsics.h"
#include "formats/dataset.h"
#include "formats/strecha.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// DTU's calibration (scan 1, view 0), as its cameras are distributed: a skew of 0.0002 px.
constexpr double kDtuFx = 2892.33, kDtuFy = 2883.18, kDtuCx = 823.206, kDtuCy = 619.071;
constexpr double kDtuSkew = 0.0002;
constexpr int kDtuWidth = 1600, kDtuHeight = 1200;

// ROOT/gt_dense_cameras/NAME.camera with K = [fx skew cx; 0 fy cy; 0 0 1], an identity rotation and
// the image file ROOT/images/NAME (empty: only its existence is checked here).
std::string WriteCamera(const fs::path& root, const std::string& name, double fx, double skew,
                        double cx = kDtuCx) {
  fs::create_directories(root / "gt_dense_cameras");
  fs::create_directories(root / "images");
  std::ofstream(root / "images" / name);
  const fs::path path = root / "gt_dense_cameras" / (name + ".camera");
  std::ofstream out(path);
  out.precision(17);
  out << fx << ' ' << skew << ' ' << cx << '\n'
      << "0 " << kDtuFy << ' ' << kDtuCy << "\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 0\n"
      << kDtuWidth << ' ' << kDtuHeight << '\n';
  return path.string();
}

const Warning* Find(const Warnings& warnings, const std::string& code) {
  for (const Warning& warning : warnings) {
    if (warning.code == code) return &warning;
  }
  return nullptr;
}

TEST(Intrinsics, DtuSkewIsDroppedWithAWarning) {
  TempDir dir("intrinsics");
  const std::string path = WriteCamera(dir.path(), "0000.jpg", kDtuFx, kDtuSkew);
  Warnings warnings;
  const StrechaCamera camera = ReadStrechaCamera(path, &warnings);
  EXPECT_EQ(camera.intrinsics.params,
            (std::array<double, kNumIntrinsics>{kDtuFx, kDtuFy, kDtuCx, kDtuCy, 0, 0, 0, 0}));
  const Warning* warning = Find(warnings, "skew_ignored");
  ASSERT_NE(warning, nullptr);
  EXPECT_EQ(warning->images, std::vector<std::string>{"0000.jpg"});
  EXPECT_DOUBLE_EQ(warning->details["max_skew"].get<double>(), kDtuSkew);
  EXPECT_NEAR(warning->details["max_effect_px"].get<double>(), kDtuSkew * kDtuHeight / kDtuFy,
              1e-12);

  // A whole scene: one warning listing every view with a skew; none without one.
  WriteCamera(dir.path(), "0001.jpg", kDtuFx, -kDtuSkew / 2);
  WriteCamera(dir.path(), "0002.jpg", kDtuFx, 0.0);
  DatasetOptions options;
  options.root = dir.path().string();
  const Dataset dataset = LoadDataset(options);
  ASSERT_EQ(dataset.warnings.size(), 1u);
  EXPECT_EQ(dataset.warnings[0].code, "skew_ignored");
  EXPECT_EQ(dataset.warnings[0].images, (std::vector<std::string>{"0000.jpg", "0001.jpg"}));
  EXPECT_EQ(dataset.images.cameras.size(), 1u);
}

TEST(Intrinsics, LargeSkewIsRefusedNamingTheFileAndTheEffect) {
  TempDir dir("intrinsics");
  const std::string path = WriteCamera(dir.path(), "0000.jpg", kDtuFx, 5.0);
  try {
    ReadStrechaCamera(path);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path + ": K has a skew of 5"), std::string::npos) << message;
    EXPECT_NE(message.find("2.08 px"), std::string::npos) << message;  // 5 x 1200 / 2883.18
  }
  // Not K's shape at all.
  Eigen::Matrix3d K;
  K << kDtuFx, 0, kDtuCx, 1, kDtuFy, kDtuCy, 0, 0, 1;
  EXPECT_THROW(IntrinsicsFromK(K, kDtuWidth, kDtuHeight, "k.txt", "a.jpg", nullptr), InputError);
}

TEST(Intrinsics, CamerasDifferingByFloatNoiseAreOneCamera) {
  TempDir dir("intrinsics");
  // DTU's per-view K differ by 0.0005 px.
  WriteCamera(dir.path(), "0000.jpg", kDtuFx, 0.0);
  WriteCamera(dir.path(), "0001.jpg", kDtuFx + 0.0005, 0.0);
  WriteCamera(dir.path(), "0002.jpg", kDtuFx - 0.0005, 0.0, kDtuCx + 0.0003);
  DatasetOptions options;
  options.root = dir.path().string();
  const Dataset dataset = LoadDataset(options);
  ASSERT_EQ(dataset.images.cameras.size(), 1u);
  EXPECT_EQ(dataset.images.cameras[0].fx(), kDtuFx);  // the first camera's values
  EXPECT_EQ(dataset.images.cameras[0].cx(), kDtuCx);
  for (const ImageInfo& image : dataset.images.images) EXPECT_EQ(image.camera_index, 0);
  const Warning* warning = Find(dataset.warnings, "cameras_merged");
  ASSERT_NE(warning, nullptr);
  EXPECT_EQ(warning->images, (std::vector<std::string>{"0001.jpg", "0002.jpg"}));
  EXPECT_EQ(warning->details["num_cameras_read"], 3);
  EXPECT_EQ(warning->details["num_cameras"], 1);
  EXPECT_NEAR(warning->details["max_difference_px"].get<double>(), 0.0005, 1e-9);
  EXPECT_NE(warning->message.find("3 per-view cameras are 1 camera"), std::string::npos)
      << warning->message;
}

TEST(Intrinsics, CamerasThatReallyDifferStayApart) {
  TempDir dir("intrinsics");
  WriteCamera(dir.path(), "0000.jpg", kDtuFx, 0.0);
  WriteCamera(dir.path(), "0001.jpg", kDtuFx + 2.0, 0.0);
  DatasetOptions options;
  options.root = dir.path().string();
  const Dataset dataset = LoadDataset(options);
  EXPECT_EQ(dataset.images.cameras.size(), 2u);
  EXPECT_EQ(dataset.images.images[1].camera_index, 1);
  EXPECT_TRUE(dataset.warnings.empty());
}

TEST(Intrinsics, MergeJoinsTheFirstCameraWithinTolerance) {
  CameraIntrinsics a;
  a.width = kDtuWidth;
  a.height = kDtuHeight;
  a.params = {kDtuFx, kDtuFy, kDtuCx, kDtuCy, 0.1, 0.01, 0, 0};
  CameraIntrinsics b = a, c = a, d = a, e = a;
  b.params[kFx] += 0.0008;  // within tolerance of a
  c.params[kFx] += 0.0016;  // within tolerance of b, not of a: its own camera
  d.params[kK1] += 1e-8;    // distortion beyond 1e-9
  e.height += 1;            // another image size
  ImageSet images;
  images.cameras = {a, b, c, d, e};
  for (int k = 0; k < 5; ++k) images.images.push_back({std::to_string(k), 0, 0, k});
  Warnings warnings;
  MergeNearlyEqualCameras(&images, &warnings);
  ASSERT_EQ(images.cameras.size(), 4u);
  EXPECT_EQ(images.cameras[0], a);
  EXPECT_EQ(images.cameras[1], c);
  std::vector<int> indices;
  for (const ImageInfo& image : images.images) indices.push_back(image.camera_index);
  EXPECT_EQ(indices, (std::vector<int>{0, 0, 1, 2, 3}));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0].images, std::vector<std::string>{"1"});

  // Exactly equal cameras (as readers already share them) are left alone, without a warning.
  ImageSet same;
  same.cameras = {a};
  same.images = {{"x", 0, 0, 0}, {"y", 0, 0, 0}};
  warnings.clear();
  MergeNearlyEqualCameras(&same, &warnings);
  EXPECT_EQ(same.cameras.size(), 1u);
  EXPECT_TRUE(warnings.empty());
}

}  // namespace
}  // namespace raytime
