#include "refine/solve/camera_blocks.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/statistics.h"

namespace raytime {
namespace {

// Grid of sample pixels per image axis (corners, edge midpoints, centre and between).
constexpr int kGridSize = 5;

// Largest distance between pixels of `from`'s image and where `to` images the same rays.
double OneWayDisagreementPx(const CameraIntrinsics& from, const CameraIntrinsics& to) {
  const double width = from.width > 0 ? from.width : 2.0 * (from.cx() + 0.5);
  const double height = from.height > 0 ? from.height : 2.0 * (from.cy() + 0.5);
  double largest = 0.0;
  for (int gy = 0; gy < kGridSize; ++gy) {
    for (int gx = 0; gx < kGridSize; ++gx) {
      const double pixel[2] = {(width - 1.0) * gx / (kGridSize - 1),
                               (height - 1.0) * gy / (kGridSize - 1)};
      double undistorted[2];
      UndistortPixel(from.params.data(), pixel, undistorted);
      const double normalized[3] = {(undistorted[0] - from.cx()) / from.fx(),
                                    (undistorted[1] - from.cy()) / from.fy(), 1.0};
      double projected[2], moved[2];
      ProjectPinhole(to.params.data(), normalized, projected);
      DistortPixel(to.params.data(), projected, moved);
      largest = std::max(largest, std::hypot(moved[0] - pixel[0], moved[1] - pixel[1]));
    }
  }
  return largest;
}

}  // namespace

CameraBlocks PerCameraBlocks(const RefineInput& input) {
  return {input.cameras, input.camera_index};
}

CameraBlocks SharedBlock(const RefineInput& input, double* max_disagreement_px) {
  CameraBlocks blocks;
  blocks.camera_of_image.assign(input.camera_index.size(), 0);
  CameraIntrinsics start = input.cameras.at(input.camera_index.empty() ? 0 : input.camera_index[0]);
  for (int camera : input.camera_index) {
    const CameraIntrinsics& given = input.cameras[camera];
    if (given.width != start.width || given.height != start.height) {
      throw InputError("refine: intrinsics_sharing 'shared' needs cameras of one image size, got " +
                       std::to_string(start.width) + "x" + std::to_string(start.height) + " and " +
                       std::to_string(given.width) + "x" + std::to_string(given.height) +
                       " (use intrinsics_sharing: per_camera)");
    }
  }
  for (int c = 0; c < kNumIntrinsics; ++c) {
    std::vector<double> values;
    values.reserve(input.camera_index.size());
    for (int camera : input.camera_index) values.push_back(input.cameras[camera].params[c]);
    start.params[c] = UpperMedian(std::move(values), start.params[c]);
  }
  double largest = 0.0;
  std::vector<bool> measured(input.cameras.size(), false);
  for (int camera : input.camera_index) {
    if (measured[camera]) continue;
    measured[camera] = true;
    largest = std::max(largest, CameraDisagreementPx(input.cameras[camera], start));
  }
  *max_disagreement_px = largest;
  blocks.cameras = {start};
  return blocks;
}

double CameraDisagreementPx(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  if (a == b) return 0.0;
  return std::max(OneWayDisagreementPx(a, b), OneWayDisagreementPx(b, a));
}

std::vector<CameraIntrinsics> InputCameras(const RefineInput& input, const CameraBlocks& solved) {
  std::vector<CameraIntrinsics> cameras = input.cameras;
  for (size_t i = 0; i < input.camera_index.size(); ++i) {
    cameras[input.camera_index[i]] = solved.Of(static_cast<int>(i));
  }
  return cameras;
}

}  // namespace raytime
