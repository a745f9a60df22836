// raytime's 3DGS renderer (splat/splat_render.h, issue 33) against analytic cases: one
// Gaussian's image is its EWA footprint (opacity × exp(−½ r² / (f²σ²/z² + 0.3))) in its SH colour;
// a nearer Gaussian hides a farther one whatever their order in the file; an elongated Gaussian
// turned by 90° about the view axis turns its footprint; the spherical harmonics are the 3DGS
// basis; the .ply reads back what was written, in the trainers' channel-major layout.
#include <gtest/gtest.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

#include "core/error.h"
#include "splat/splat_render.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr float kSh0 = 0.28209479177387814f;
constexpr float kSh1 = 0.4886025119029199f;

CameraIntrinsics Pinhole(int size, double focal) {
  CameraIntrinsics camera;
  camera.width = camera.height = size;
  camera.params = {focal, focal, (size - 1) / 2.0, (size - 1) / 2.0, 0, 0, 0, 0};
  return camera;
}

// One Gaussian at `mean` with isotropic scale `sigma`, opacity logit `logit`, SH degree 0 of
// colour `rgb` (after the +0.5 offset).
void AddSplat(GaussianSplats* splats, const Eigen::Vector3f& mean, float sigma, float logit,
              const Eigen::Vector3f& rgb) {
  splats->means.push_back(mean);
  splats->log_scales.push_back(Eigen::Vector3f::Constant(std::log(sigma)));
  splats->rotations.emplace_back(1, 0, 0, 0);
  splats->opacity_logits.push_back(logit);
  splats->sh.push_back((rgb.array() - 0.5f) / kSh0);
}

TEST(SplatRenderTest, OneGaussianIsItsEwaFootprintInItsColour) {
  GaussianSplats splats;
  const Eigen::Vector3f rgb(0.8f, 0.6f, 0.3f);
  AddSplat(&splats, Eigen::Vector3f(0, 0, 5), 0.1f, 2.0f, rgb);
  const CameraIntrinsics camera = Pinhole(64, 100.0);
  const cv::Mat image = RenderGaussianSplats(splats, camera, Rigid3());
  ASSERT_EQ(image.type(), CV_32FC3);
  const double opacity = 1.0 / (1.0 + std::exp(-2.0));
  const double variance = std::pow(100.0 * 0.1 / 5.0, 2) + 0.3;  // (fσ/z)² + the low-pass
  double largest_error = 0.0;
  for (int v = 0; v < 64; ++v) {
    for (int u = 0; u < 64; ++u) {
      const double r2 = std::pow(u - 31.5, 2) + std::pow(v - 31.5, 2);
      double alpha = std::min(0.999, opacity * std::exp(-0.5 * r2 / variance));
      if (alpha < 1.0 / 255) alpha = 0.0;
      const cv::Vec3f bgr = image.at<cv::Vec3f>(v, u);
      for (int c = 0; c < 3; ++c) {
        largest_error = std::max(largest_error, std::abs(bgr[2 - c] - rgb(c) * alpha));
      }
    }
  }
  EXPECT_LT(largest_error, 2e-6);

  // Rasterizers that ignore the principal point (the Inria code, OpenSplat on the CPU) put it at
  // the centre: a camera whose cx, cy are off centre renders as the centred one.
  CameraIntrinsics off_centre = camera;
  off_centre.params[kCx] += 3.0;
  off_centre.params[kCy] -= 2.0;
  SplatRenderOptions centred;
  centred.centred_principal_point = true;
  EXPECT_EQ(
      cv::norm(RenderGaussianSplats(splats, off_centre, Rigid3(), centred), image, cv::NORM_INF),
      0.0);
  EXPECT_GT(cv::norm(RenderGaussianSplats(splats, off_centre, Rigid3()), image, cv::NORM_INF), 0.1);
}

TEST(SplatRenderTest, TheNearerGaussianHidesTheFartherWhateverTheirOrder) {
  const Eigen::Vector3f red(1, 0, 0), green(0, 1, 0);
  GaussianSplats near_first, far_first;
  AddSplat(&near_first, Eigen::Vector3f(0, 0, 4), 0.2f, 6.0f, red);
  AddSplat(&near_first, Eigen::Vector3f(0, 0, 8), 0.4f, 6.0f, green);
  AddSplat(&far_first, Eigen::Vector3f(0, 0, 8), 0.4f, 6.0f, green);
  AddSplat(&far_first, Eigen::Vector3f(0, 0, 4), 0.2f, 6.0f, red);
  SplatRenderOptions options;
  options.background = Eigen::Vector3f(0, 0, 1);
  const CameraIntrinsics camera = Pinhole(48, 80.0);
  const cv::Mat a = RenderGaussianSplats(near_first, camera, Rigid3(), options);
  const cv::Mat b = RenderGaussianSplats(far_first, camera, Rigid3(), options);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  // At the centre: red at α1, green through (1 − α1), the background through what is left.
  const double opacity = 1.0 / (1.0 + std::exp(-6.0));
  const double alpha_red = std::min(0.999, opacity * std::exp(-0.5 * 0.5 / (16.0 + 0.3)));
  const double alpha_green = std::min(0.999, opacity * std::exp(-0.5 * 0.5 / (16.0 + 0.3)));
  const cv::Vec3f centre = a.at<cv::Vec3f>(23, 23);  // 0.5 px from the projection on each axis
  EXPECT_NEAR(centre[2], alpha_red, 1e-5);
  EXPECT_NEAR(centre[1], (1 - alpha_red) * alpha_green, 1e-5);
  EXPECT_NEAR(centre[0], (1 - alpha_red) * (1 - alpha_green), 1e-5);
  // Far from both: the background.
  EXPECT_EQ(a.at<cv::Vec3f>(0, 0), cv::Vec3f(1, 0, 0));
}

TEST(SplatRenderTest, AnElongatedGaussianTurnedAboutTheViewAxisTurnsItsFootprint) {
  GaussianSplats splats;
  AddSplat(&splats, Eigen::Vector3f(0, 0, 5), 0.05f, 4.0f, Eigen::Vector3f(1, 1, 1));
  splats.log_scales[0] = Eigen::Vector3f(std::log(0.3f), std::log(0.05f), std::log(0.05f));
  const CameraIntrinsics camera = Pinhole(65, 100.0);  // the projection on pixel (32, 32)
  const cv::Mat along_x = RenderGaussianSplats(splats, camera, Rigid3());
  const Eigen::Quaternionf quarter(
      Eigen::AngleAxisf(static_cast<float>(M_PI / 2), Eigen::Vector3f::UnitZ()));
  splats.rotations[0] = Eigen::Vector4f(quarter.w(), quarter.x(), quarter.y(), quarter.z());
  const cv::Mat along_y = RenderGaussianSplats(splats, camera, Rigid3());
  EXPECT_GT(along_x.at<cv::Vec3f>(32, 37)[0], 0.5f);   // 5 px to the right: inside (σ 6 px)
  EXPECT_LT(along_x.at<cv::Vec3f>(37, 32)[0], 0.01f);  // 5 px down: outside (σ 1.1 px)
  // Turned: the transpose, to float rounding.
  cv::Mat transposed;
  cv::transpose(along_x, transposed);
  EXPECT_LT(cv::norm(along_y, transposed, cv::NORM_INF), 1e-5);
}

// A Gaussian of size 0 (log scale −∞: OpenSplat starts one where three neighbours coincide) is
// drawn as the low-pass alone, variance 0.3 px².
TEST(SplatRenderTest, AGaussianOfSizeZeroIsTheLowPassFootprint) {
  GaussianSplats splats;
  AddSplat(&splats, Eigen::Vector3f(0, 0, 5), 1.0f, 1.0f, Eigen::Vector3f(1, 1, 1));
  splats.log_scales[0] = Eigen::Vector3f::Constant(-std::numeric_limits<float>::infinity());
  EXPECT_EQ(CountNonFiniteGaussians(splats), 0u);
  const cv::Mat image = RenderGaussianSplats(splats, Pinhole(64, 100.0), Rigid3());
  const double opacity = 1.0 / (1.0 + std::exp(-1.0));
  EXPECT_NEAR(image.at<cv::Vec3f>(31, 31)[0], opacity * std::exp(-0.5 * 0.5 / 0.3), 1e-6);
  EXPECT_EQ(image.at<cv::Vec3f>(31, 35)[0], 0.0f);  // 3.5 px away: below 1/255
}

TEST(SplatRenderTest, AGaussianBehindTheCameraOrOutOfViewIsNotDrawn) {
  GaussianSplats splats;
  AddSplat(&splats, Eigen::Vector3f(0, 0, -5), 1.0f, 6.0f, Eigen::Vector3f(1, 1, 1));
  AddSplat(&splats, Eigen::Vector3f(50, 0, 5), 0.1f, 6.0f, Eigen::Vector3f(1, 1, 1));
  const cv::Mat image = RenderGaussianSplats(splats, Pinhole(32, 50.0), Rigid3());
  EXPECT_EQ(cv::norm(image, cv::NORM_INF), 0.0);
}

TEST(SplatRenderTest, SphericalHarmonicsAreThe3dgsBasis) {
  Eigen::VectorXf sh = Eigen::VectorXf::Zero(3 * 16);
  sh.segment<3>(0) << 1, 2, 3;
  sh.segment<3>(3 * 2) << 0.5f, 0, 0;   // coefficient 2: kSh1 · z
  sh.segment<3>(3 * 6) << 0, 0.25f, 0;  // coefficient 6: kSh2[2] · (2z² − x² − y²)
  const Eigen::Vector3f dc = kSh0 * Eigen::Vector3f(1, 2, 3);
  EXPECT_LT((EvaluateSphericalHarmonics(sh, 0, Eigen::Vector3f(0, 0, 1)) - dc).norm(), 1e-6);
  const Eigen::Vector3f up = EvaluateSphericalHarmonics(sh, 2, Eigen::Vector3f(0, 0, 1));
  EXPECT_NEAR(up.x(), dc.x() + kSh1 * 0.5f, 1e-6);
  EXPECT_NEAR(up.y(), dc.y() + 0.31539156525252005f * 2 * 0.25f, 1e-6);
  const Eigen::Vector3f side = EvaluateSphericalHarmonics(sh, 2, Eigen::Vector3f(1, 0, 0));
  EXPECT_NEAR(side.x(), dc.x(), 1e-6);  // z = 0
  EXPECT_NEAR(side.y(), dc.y() - 0.31539156525252005f * 0.25f, 1e-6);
}

class SplatPlyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("raytime_splat_ply_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(SplatPlyTest, ReadsBackWhatWasWrittenInTheTrainersLayout) {
  GaussianSplats splats;
  splats.sh_degree = 3;
  std::mt19937 random(7);
  std::normal_distribution<float> normal;
  for (int g = 0; g < 5; ++g) {
    splats.means.emplace_back(normal(random), normal(random), normal(random));
    splats.log_scales.emplace_back(normal(random), normal(random), normal(random));
    splats.rotations.emplace_back(normal(random), normal(random), normal(random), normal(random));
    splats.opacity_logits.push_back(normal(random));
    Eigen::VectorXf sh(48);
    for (int k = 0; k < 48; ++k) sh(k) = normal(random);
    splats.sh.push_back(sh);
  }
  const std::string path = (dir_ / "point_cloud.ply").string();
  WriteGaussianSplatPly(splats, path);
  const GaussianSplats read = ReadGaussianSplatPly(path);
  ASSERT_EQ(read.size(), 5u);
  EXPECT_EQ(read.sh_degree, 3);
  for (size_t g = 0; g < 5; ++g) {
    EXPECT_EQ(read.means[g], splats.means[g]);
    EXPECT_EQ(read.log_scales[g], splats.log_scales[g]);
    EXPECT_EQ(read.rotations[g], splats.rotations[g]);
    EXPECT_EQ(read.opacity_logits[g], splats.opacity_logits[g]);
    EXPECT_EQ(read.sh[g], splats.sh[g]);
  }
  // The file's layout: per Gaussian x y z nx ny nz f_dc_0..2 f_rest_0..44 ...; f_rest is
  // channel-major (red's 15 coefficients, then green's), as the 3DGS trainers write it.
  std::ifstream in(path, std::ios::binary);
  std::string line;
  while (std::getline(in, line) && line != "end_header") {
  }
  float record[9 + 45];
  in.read(reinterpret_cast<char*>(record), sizeof(record));
  EXPECT_EQ(record[9], splats.sh[0](3 * 1 + 0));        // f_rest_0: red, coefficient 1
  EXPECT_EQ(record[9 + 15], splats.sh[0](3 * 1 + 1));   // f_rest_15: green, coefficient 1
  EXPECT_EQ(record[9 + 44], splats.sh[0](3 * 15 + 2));  // f_rest_44: blue, coefficient 15
}

TEST_F(SplatPlyTest, AFileThatIsNoSplatSaysWhy) {
  const auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name, std::ios::binary) << text;
    return (dir_ / name).string();
  };
  const auto error_of = [](const std::string& path) {
    try {
      ReadGaussianSplatPly(path);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of(write("a.ply", "solid cube\n")).find("not a PLY file"), std::string::npos);
  const std::string points =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n";
  EXPECT_NE(error_of(write("b.ply", points)).find("no 'opacity' property"), std::string::npos);
  GaussianSplats one;
  AddSplat(&one, Eigen::Vector3f(0, 0, 1), 1.0f, 0.0f, Eigen::Vector3f(1, 1, 1));
  const std::string path = (dir_ / "c.ply").string();
  WriteGaussianSplatPly(one, path);
  fs::resize_file(path, fs::file_size(path) - 4);
  EXPECT_NE(error_of(path).find("truncated"), std::string::npos);
  EXPECT_NE(error_of((dir_ / "none.ply").string()).find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace raytime
