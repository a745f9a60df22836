#include "core/intrinsics.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"

namespace raytime {
namespace {

// "0.000187" / "8.3e-05": three significant digits, for messages.
std::string Short(double value) {
  std::ostringstream out;
  out.precision(3);
  out << value;
  return out.str();
}

// The one "skew_ignored" warning of `warnings`, created on first use.
Warning* SkewWarning(Warnings* warnings) {
  for (Warning& warning : *warnings) {
    if (warning.code == "skew_ignored") return &warning;
  }
  Warning warning;
  warning.code = "skew_ignored";
  warning.details = {
      {"max_skew", 0.0}, {"max_effect_px", 0.0}, {"tolerance_px", kNegligibleSkewPx}};
  warnings->push_back(warning);
  return &warnings->back();
}

double MaxPixelDifference(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  double difference = 0.0;
  for (const int k : {kFx, kFy, kCx, kCy}) {
    difference = std::max(difference, std::abs(a.params[k] - b.params[k]));
  }
  return difference;
}

double MaxDistortionDifference(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  double difference = 0.0;
  for (const int k : {kK1, kK2, kP1, kP2}) {
    difference = std::max(difference, std::abs(a.params[k] - b.params[k]));
  }
  return difference;
}

}  // namespace

CameraIntrinsics IntrinsicsFromK(const Eigen::Matrix3d& K, int width, int height,
                                 const std::string& path, const std::string& image,
                                 Warnings* warnings) {
  if (K(1, 0) != 0 || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1) {
    ThrowInput(path, 0, "K must be [fx s cx; 0 fy cy; 0 0 1]");
  }
  if (!(K(0, 0) > 0) || !(K(1, 1) > 0)) {
    ThrowInput(path, 0, "K's focal lengths fx = K[0][0] and fy = K[1][1] must be positive");
  }
  const double skew = K(0, 1);
  const double effect_px = std::abs(skew) * height / K(1, 1);
  if (effect_px > kNegligibleSkewPx) {
    ThrowInput(path, 0,
               "K has a skew of " + Short(skew) + " (K[0][1]) that moves pixels by up to " +
                   Short(effect_px) + " px over the image (|skew| x height / fy), more than the " +
                   Short(kNegligibleSkewPx) +
                   " px that can be ignored; raytime's camera model has no skew");
  }
  if (skew != 0 && warnings != nullptr) {
    Warning* warning = SkewWarning(warnings);
    warning->images.push_back(image);
    nlohmann::json& details = warning->details;
    details["max_skew"] = std::max(details["max_skew"].get<double>(), std::abs(skew));
    details["max_effect_px"] = std::max(details["max_effect_px"].get<double>(), effect_px);
    warning->message = "K has a skew in " + std::to_string(warning->images.size()) +
                       " camera(s) (up to " + Short(details["max_skew"].get<double>()) +
                       ", moving pixels by at most " +
                       Short(details["max_effect_px"].get<double>()) + " px, below the " +
                       Short(kNegligibleSkewPx) + " px tolerance); it was set to 0";
  }
  CameraIntrinsics intrinsics;
  intrinsics.width = width;
  intrinsics.height = height;
  intrinsics.params = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), 0, 0, 0, 0};
  return intrinsics;
}

void MergeNearlyEqualCameras(ImageSet* images, Warnings* warnings) {
  const std::vector<CameraIntrinsics>& cameras = images->cameras;
  std::vector<int> new_index(cameras.size());
  std::vector<int> kept;  // indices into `cameras` of the cameras that remain
  std::vector<bool> merged(cameras.size(), false);
  double max_px = 0.0, max_distortion = 0.0;
  for (size_t c = 0; c < cameras.size(); ++c) {
    const auto same = std::find_if(kept.begin(), kept.end(), [&](int k) {
      const CameraIntrinsics& a = cameras[c];
      const CameraIntrinsics& b = cameras[k];
      return a.width == b.width && a.height == b.height &&
             MaxPixelDifference(a, b) <= kSameCameraPx &&
             MaxDistortionDifference(a, b) <= kSameCameraDistortion;
    });
    if (same == kept.end()) {
      new_index[c] = static_cast<int>(kept.size());
      kept.push_back(static_cast<int>(c));
      continue;
    }
    new_index[c] = static_cast<int>(same - kept.begin());
    merged[c] = true;
    max_px = std::max(max_px, MaxPixelDifference(cameras[c], cameras[*same]));
    max_distortion = std::max(max_distortion, MaxDistortionDifference(cameras[c], cameras[*same]));
  }
  if (kept.size() == cameras.size()) return;

  Warning warning;
  warning.code = "cameras_merged";
  for (ImageInfo& image : images->images) {
    if (merged[image.camera_index]) warning.images.push_back(image.name);
    image.camera_index = new_index[image.camera_index];
  }
  std::vector<CameraIntrinsics> remaining;
  for (const int k : kept) remaining.push_back(cameras[k]);
  warning.message = std::to_string(cameras.size()) + " per-view cameras are " +
                    std::to_string(remaining.size()) +
                    " camera(s): their intrinsics differ by at most " + Short(max_px) +
                    " px (tolerance " + Short(kSameCameraPx) +
                    " px); each merged view takes the values of the first camera it matches";
  warning.details = {
      {"num_cameras_read", cameras.size()}, {"num_cameras", remaining.size()},
      {"max_difference_px", max_px},        {"max_distortion_difference", max_distortion},
      {"tolerance_px", kSameCameraPx},      {"tolerance_distortion", kSameCameraDistortion}};
  images->cameras = std::move(remaining);
  if (warnings != nullptr) warnings->push_back(warning);
}

}  // namespace raytime
