#include "splat/image_metrics.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "core/error.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// Values on [0, 1] in double precision, colour channels only (the trainers drop alpha too).
cv::Mat UnitValues(const cv::Mat& image) {
  double scale = 1.0;
  switch (image.depth()) {
    case CV_8U:
      scale = 1.0 / 255.0;
      break;
    case CV_16U:
      scale = 1.0 / 65535.0;
      break;
    case CV_32F:
    case CV_64F:
      break;
    default:
      throw InputError("image metrics: unsupported pixel depth " + std::to_string(image.depth()));
  }
  cv::Mat values;
  image.convertTo(values, CV_64F, scale);
  // Grey + alpha, or BGR + alpha: the colour planes only (cvtColor has no 64-bit path).
  if (values.channels() == 2 || values.channels() == 4) {
    std::vector<cv::Mat> planes;
    cv::split(values, planes);
    planes.pop_back();
    cv::merge(planes, values);
  }
  return values;
}

void RequireSameShape(const cv::Mat& render, const cv::Mat& reference) {
  if (render.empty() || reference.empty()) throw InputError("image metrics: an image is empty");
  if (render.size() != reference.size()) {
    throw InputError("image metrics: the render is " + std::to_string(render.cols) + "x" +
                     std::to_string(render.rows) + " but its ground truth " +
                     std::to_string(reference.cols) + "x" + std::to_string(reference.rows));
  }
}

// Both images on [0, 1] with the same colour channels; a grey image beside a colour one is
// compared as grey repeated, as a trainer's RGB loader would read it.
void UnitPair(const cv::Mat& render, const cv::Mat& reference, cv::Mat* a, cv::Mat* b) {
  RequireSameShape(render, reference);
  *a = UnitValues(render);
  *b = UnitValues(reference);
  const auto grey_as_colour = [](cv::Mat* image) {
    cv::merge(std::vector<cv::Mat>{*image, *image, *image}, *image);
  };
  if (a->channels() == 1 && b->channels() == 3) grey_as_colour(a);
  if (b->channels() == 1 && a->channels() == 3) grey_as_colour(b);
  if (a->channels() != b->channels()) {
    throw InputError("image metrics: the render has " + std::to_string(a->channels()) +
                     " channels but its ground truth " + std::to_string(b->channels()));
  }
}

double SsimOfPlane(const cv::Mat& x, const cv::Mat& y) {
  // Wang et al. 2004 with the constants every 3DGS trainer uses (K1 = 0.01, K2 = 0.03, L = 1).
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  const cv::Size window(11, 11);
  constexpr double kSigma = 1.5;
  cv::Mat mu_x, mu_y, xx, yy, xy;
  cv::GaussianBlur(x, mu_x, window, kSigma);
  cv::GaussianBlur(y, mu_y, window, kSigma);
  cv::GaussianBlur(x.mul(x), xx, window, kSigma);
  cv::GaussianBlur(y.mul(y), yy, window, kSigma);
  cv::GaussianBlur(x.mul(y), xy, window, kSigma);
  const cv::Mat mu_xx = mu_x.mul(mu_x);
  const cv::Mat mu_yy = mu_y.mul(mu_y);
  const cv::Mat mu_xy = mu_x.mul(mu_y);
  const cv::Mat sigma_xx = xx - mu_xx;
  const cv::Mat sigma_yy = yy - mu_yy;
  const cv::Mat sigma_xy = xy - mu_xy;
  cv::Mat numerator = (2 * mu_xy + kC1).mul(2 * sigma_xy + kC2);
  cv::Mat denominator = (mu_xx + mu_yy + kC1).mul(sigma_xx + sigma_yy + kC2);
  cv::Mat map;
  cv::divide(numerator, denominator, map);
  return cv::mean(map)[0];
}

bool IsImageFile(const fs::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static const std::set<std::string> kExtensions = {".png", ".jpg",  ".jpeg", ".exr",
                                                    ".tif", ".tiff", ".bmp"};
  return kExtensions.count(extension) > 0;
}

cv::Mat ReadImageFile(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "image not found");
  // Unchanged: 16-bit stays 16-bit, and no EXIF rotation (the trainers read pixels as stored).
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty()) ThrowInput(path, 0, "cannot decode the image");
  return image;
}

}  // namespace

double Psnr(const cv::Mat& render, const cv::Mat& reference) {
  cv::Mat a, b;
  UnitPair(render, reference, &a, &b);
  const cv::Mat difference = a - b;
  const cv::Scalar sums = cv::sum(difference.mul(difference));  // one sum per channel
  double total = 0.0;
  for (int c = 0; c < difference.channels(); ++c) total += sums[c];
  const double mse = total / static_cast<double>(difference.total() * difference.channels());
  if (mse == 0.0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

double Ssim(const cv::Mat& render, const cv::Mat& reference) {
  cv::Mat a, b;
  UnitPair(render, reference, &a, &b);
  std::vector<cv::Mat> planes_a, planes_b;
  cv::split(a, planes_a);
  cv::split(b, planes_b);
  double sum = 0.0;
  for (size_t c = 0; c < planes_a.size(); ++c) sum += SsimOfPlane(planes_a[c], planes_b[c]);
  return sum / static_cast<double>(planes_a.size());
}

HeldOutScore ScoreHeldOutViews(const std::vector<HeldOutView>& views) {
  HeldOutScore score;
  if (views.empty()) return score;
  double psnr_sum = 0.0, ssim_sum = 0.0;
  for (const HeldOutView& view : views) {
    cv::Mat render = ReadImageFile(view.render_path);
    cv::Mat reference;
    if (view.reference_path.empty()) {
      // Side by side: [ground truth | render], each half the width.
      if (render.cols % 2 != 0) {
        ThrowInput(view.render_path, 0,
                   "a side-by-side evaluation image (ground truth | render) must have an even "
                   "width, got " +
                       std::to_string(render.cols));
      }
      const int half = render.cols / 2;
      reference = render(cv::Rect(0, 0, half, render.rows)).clone();
      render = render(cv::Rect(half, 0, half, render.rows)).clone();
    } else {
      reference = ReadImageFile(view.reference_path);
    }
    try {
      psnr_sum += Psnr(render, reference);
      ssim_sum += Ssim(render, reference);
    } catch (const InputError& e) {
      ThrowInput(view.render_path, 0, e.what());
    }
    ++score.num_images;
  }
  score.psnr = psnr_sum / score.num_images;
  score.ssim = ssim_sum / score.num_images;
  return score;
}

std::vector<HeldOutView> ViewsOfFolderPair(const std::string& renders_dir,
                                           const std::string& gt_dir) {
  if (!fs::is_directory(renders_dir)) ThrowInput(renders_dir, 0, "renders folder not found");
  if (!fs::is_directory(gt_dir)) ThrowInput(gt_dir, 0, "ground-truth folder not found");
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(renders_dir)) {
    if (entry.is_regular_file() && IsImageFile(entry.path())) {
      names.push_back(entry.path().filename().string());
    }
  }
  std::sort(names.begin(), names.end());
  if (names.empty()) ThrowInput(renders_dir, 0, "no image in the renders folder");
  std::vector<HeldOutView> views;
  for (const auto& name : names) {
    const fs::path reference = fs::path(gt_dir) / name;
    if (!fs::is_regular_file(reference)) {
      ThrowInput(reference.string(), 0, "the render " + name + " has no ground truth of that name");
    }
    views.push_back({(fs::path(renders_dir) / name).string(), reference.string()});
  }
  return views;
}

}  // namespace raytime
