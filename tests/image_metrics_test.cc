// raytime's own PSNR and SSIM (splat/image_metrics.h) against answers derived by hand:
// noise of known energy, constant images, a checkerboard against its inverse and against a
// contrast-scaled copy (whose local statistics are exact because a period-2 pattern is its own
// mirror image at every border), and the folder layouts the trainers write.
#include "splat/image_metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "core/error.h"
#include "tests/temp_dir.h"

namespace raytime {
namespace {

constexpr double kC1 = 0.01 * 0.01;
constexpr double kC2 = 0.03 * 0.03;

// A period-2 checkerboard a ± d on [0, 1], one channel, double precision.
cv::Mat Checkerboard(int rows, int cols, double a, double d) {
  cv::Mat image(rows, cols, CV_64F);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) image.at<double>(r, c) = (r + c) % 2 == 0 ? a + d : a - d;
  }
  return image;
}

TEST(ImageMetrics, PsnrOfAlternatingNoiseIsExact) {
  // Grey 128 with +8 / -8 alternating: MSE = (8/255)^2 exactly, PSNR = 20 log10(255/8).
  cv::Mat reference(48, 64, CV_8UC3, cv::Scalar(128, 128, 128));
  cv::Mat render = reference.clone();
  for (int r = 0; r < render.rows; ++r) {
    for (int c = 0; c < render.cols; ++c) {
      const uchar value = (r + c) % 2 == 0 ? 136 : 120;
      render.at<cv::Vec3b>(r, c) = {value, value, value};
    }
  }
  EXPECT_NEAR(Psnr(render, reference), 20.0 * std::log10(255.0 / 8.0), 1e-9);
  EXPECT_NEAR(Psnr(reference, render), 30.0690, 1e-4);
}

TEST(ImageMetrics, PsnrOfUniformNoiseIsExact) {
  // Integer noise uniform on {-10, ..., 10}, each value equally often (in random order): its
  // energy is k(k + 1)/3 = 110/3 grey levels squared, so PSNR = 10 log10(3 * 255^2 / 110).
  const int k = 10;
  std::vector<int> noise;
  for (int repeat = 0; repeat < 64; ++repeat) {
    for (int n = -k; n <= k; ++n) noise.push_back(n);
  }
  std::shuffle(noise.begin(), noise.end(), std::mt19937(7));
  cv::Mat reference(21, 64, CV_8UC1, cv::Scalar(100));
  cv::Mat render(21, 64, CV_8UC1);
  for (int i = 0; i < static_cast<int>(noise.size()); ++i) {
    render.at<uchar>(i / 64, i % 64) = static_cast<uchar>(100 + noise[i]);
  }
  const double expected = 10.0 * std::log10(3.0 * 255.0 * 255.0 / (k * (k + 1)));
  EXPECT_NEAR(Psnr(render, reference), expected, 1e-9);
  EXPECT_NEAR(expected, 32.4881, 1e-4);

  // 16-bit images at 257x the 8-bit values are the same [0, 1] values: the same PSNR.
  cv::Mat render16, reference16;
  render.convertTo(render16, CV_16U, 257.0);
  reference.convertTo(reference16, CV_16U, 257.0);
  EXPECT_NEAR(Psnr(render16, reference16), expected, 1e-9);
}

TEST(ImageMetrics, IdenticalImagesScoreOneAndInfinity) {
  cv::Mat image(40, 56, CV_8UC3);
  cv::randu(image, 0, 256);
  EXPECT_DOUBLE_EQ(Ssim(image, image), 1.0);
  EXPECT_TRUE(std::isinf(Psnr(image, image)));
  EXPECT_GT(Psnr(image, image), 0.0);
}

TEST(ImageMetrics, SsimOfConstantImagesIsTheLuminanceTerm) {
  // No variance anywhere: SSIM = (2ab + C1) / (a^2 + b^2 + C1).
  const double a = 0.5, b = 0.25;
  const cv::Mat x(32, 32, CV_64F, cv::Scalar(a));
  const cv::Mat y(32, 32, CV_64F, cv::Scalar(b));
  const double expected = (2 * a * b + kC1) / (a * a + b * b + kC1);
  EXPECT_NEAR(Ssim(x, y), expected, 1e-12);
  EXPECT_NEAR(expected, 0.800064, 1e-6);
}

TEST(ImageMetrics, SsimOfACheckerboardAgainstItsInverseAndAScaledCopy) {
  // Under the 11x11, sigma 1.5 window a checkerboard a ± d has local mean a and variance d^2 (the
  // window's response at the Nyquist frequency is ~1e-10), everywhere including the borders.
  const double a = 0.5, d = 0.25;
  const cv::Mat x = Checkerboard(40, 48, a, d);
  // Inverse: covariance -d^2, so SSIM = (C2 - 2 d^2) / (C2 + 2 d^2).
  const cv::Mat inverse = Checkerboard(40, 48, a, -d);
  EXPECT_NEAR(Ssim(inverse, x), (kC2 - 2 * d * d) / (kC2 + 2 * d * d), 1e-8);
  EXPECT_NEAR(Ssim(inverse, x), -0.985703, 1e-6);
  // Contrast scaled by k around the mean: SSIM = (2 k d^2 + C2) / ((1 + k^2) d^2 + C2).
  const double k = 0.5;
  const cv::Mat scaled = Checkerboard(40, 48, a, k * d);
  EXPECT_NEAR(Ssim(scaled, x), (2 * k * d * d + kC2) / ((1 + k * k) * d * d + kC2), 1e-8);
  EXPECT_NEAR(Ssim(scaled, x), 0.802278, 1e-6);
}

TEST(ImageMetrics, SsimIsTheMeanOverChannels) {
  const double a = 0.5, d = 0.25;
  const cv::Mat checker = Checkerboard(32, 40, a, d);
  const cv::Mat inverse = Checkerboard(32, 40, a, -d);
  const cv::Mat half(32, 40, CV_64F, cv::Scalar(0.5));
  const cv::Mat quarter(32, 40, CV_64F, cv::Scalar(0.25));
  cv::Mat render, reference;
  cv::merge(std::vector<cv::Mat>{checker, half, inverse}, render);
  cv::merge(std::vector<cv::Mat>{checker, quarter, checker}, reference);
  const double expected =
      (1.0 + (2 * 0.125 + kC1) / (0.25 + 0.0625 + kC1) + (kC2 - 2 * d * d) / (kC2 + 2 * d * d)) /
      3.0;
  EXPECT_NEAR(Ssim(render, reference), expected, 1e-8);
}

TEST(ImageMetrics, AlphaIsDroppedAndShapesMustAgree) {
  cv::Mat colour(16, 16, CV_8UC3);
  cv::randu(colour, 0, 256);
  cv::Mat noisy = colour.clone();
  cv::randu(noisy(cv::Rect(0, 0, 8, 8)), 0, 256);
  cv::Mat with_alpha, noisy_alpha;
  cv::cvtColor(colour, with_alpha, cv::COLOR_BGR2BGRA);
  cv::cvtColor(noisy, noisy_alpha, cv::COLOR_BGR2BGRA);
  noisy_alpha.forEach<cv::Vec4b>([](cv::Vec4b& p, const int*) { p[3] = 7; });
  EXPECT_DOUBLE_EQ(Psnr(noisy_alpha, with_alpha), Psnr(noisy, colour));
  EXPECT_DOUBLE_EQ(Ssim(noisy_alpha, with_alpha), Ssim(noisy, colour));
  EXPECT_THROW(Psnr(colour, cv::Mat(16, 17, CV_8UC3)), InputError);
  EXPECT_THROW(Ssim(colour, cv::Mat()), InputError);
}

// Writes an 8-bit image; the test's folders mimic the trainers' layouts.
void Write(const std::string& path, const cv::Mat& image) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  ASSERT_TRUE(cv::imwrite(path, image)) << path;
}

TEST(ImageMetrics, FolderPairsAndSideBySideFilesScoreAlike) {
  TempDir dir("image_metrics");
  cv::Mat gt0(24, 32, CV_8UC3), gt1(24, 32, CV_8UC3);
  cv::randu(gt0, 0, 256);
  cv::randu(gt1, 0, 256);
  cv::Mat render0 = gt0.clone(), render1 = gt1.clone();
  cv::randu(render0(cv::Rect(0, 0, 16, 24)), 0, 256);
  cv::randu(render1(cv::Rect(8, 4, 8, 8)), 0, 256);
  Write(dir / "renders/00000.png", render0);
  Write(dir / "renders/00001.png", render1);
  Write(dir / "gt/00000.png", gt0);
  Write(dir / "gt/00001.png", gt1);
  std::filesystem::create_directories(dir / "renders/notes");
  Write(dir / "renders/extra.png", render0);  // an image without ground truth
  EXPECT_THROW(ViewsOfFolderPair(dir / "renders", dir / "gt"), InputError);
  std::filesystem::remove(dir / "renders/extra.png");

  const std::vector<HeldOutView> views = ViewsOfFolderPair(dir / "renders", dir / "gt");
  ASSERT_EQ(views.size(), 2u);
  EXPECT_EQ(std::filesystem::path(views[0].render_path).filename(), "00000.png");
  const HeldOutScore pair = ScoreHeldOutViews(views);
  EXPECT_EQ(pair.num_images, 2);
  EXPECT_NEAR(pair.psnr, (Psnr(render0, gt0) + Psnr(render1, gt1)) / 2, 1e-12);
  EXPECT_NEAR(pair.ssim, (Ssim(render0, gt0) + Ssim(render1, gt1)) / 2, 1e-12);

  // gsplat / nerfstudio: [ground truth | render] in one file.
  cv::Mat side0, side1;
  cv::hconcat(gt0, render0, side0);
  cv::hconcat(gt1, render1, side1);
  Write(dir / "side/val_step6999_0000.png", side0);
  Write(dir / "side/val_step6999_0001.png", side1);
  const HeldOutScore side = ScoreHeldOutViews(
      {{dir / "side/val_step6999_0000.png", ""}, {dir / "side/val_step6999_0001.png", ""}});
  EXPECT_EQ(side.num_images, 2);
  EXPECT_DOUBLE_EQ(side.psnr, pair.psnr);
  EXPECT_DOUBLE_EQ(side.ssim, pair.ssim);

  Write(dir / "side/odd.png", cv::Mat(8, 9, CV_8UC3, cv::Scalar(1, 2, 3)));
  EXPECT_THROW(ScoreHeldOutViews({{dir / "side/odd.png", ""}}), InputError);
  EXPECT_THROW(ScoreHeldOutViews({{dir / "side/missing.png", ""}}), InputError);
  EXPECT_THROW(ViewsOfFolderPair(dir / "nothing", dir / "gt"), InputError);
  EXPECT_EQ(ScoreHeldOutViews({}).num_images, 0);
}

}  // namespace
}  // namespace raytime
