// Match quality against ground truth (issue 3; not a test, and outside frontend/ because the
// front end never sees ground truth).
//
//   match_quality --workdir DIR [--max-epipolar-px 4] [--pairs]
//
// DIR is a pipeline work directory holding dataset.h5 (images and the ground-truth pose set),
// features.h5 and matches.h5. For every verified pair it compares the stored relative rotation
// cam2_from_cam1 with the ground truth's, and measures each inlier's distance to the ground-truth
// epipolar lines (mean of the two point-to-line distances, pixels, undistorted keypoints). Prints
// the median and 90th percentile of the rotation errors over pairs, the pairs whose median
// epipolar error exceeds --max-epipolar-px ("wrong pairs", the measure of
// ../shared/data/README.md) and the share of inliers more than 10 px off.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_main.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/hdf5_store.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return std::nan("");
  std::sort(values.begin(), values.end());
  const double position = q * (values.size() - 1);
  const size_t below = static_cast<size_t>(std::floor(position));
  const size_t above = std::min(values.size() - 1, below + 1);
  return values[below] + (position - below) * (values[above] - values[below]);
}

Eigen::Vector2d Undistorted(const CameraIntrinsics& camera, const ImageFeatures& features,
                            uint32_t k) {
  const double distorted[2] = {features.keypoints(k, 0), features.keypoints(k, 1)};
  double out[2] = {distorted[0], distorted[1]};
  if (camera.HasDistortion()) UndistortPixel(camera.params.data(), distorted, out);
  return {out[0], out[1]};
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

Eigen::Matrix3d InversePinhole(const CameraIntrinsics& c) {
  Eigen::Matrix3d K;
  K << c.fx(), 0, c.cx(), 0, c.fy(), c.cy(), 0, 0, 1;
  return K.inverse();
}

double LineDistance(const Eigen::Vector3d& line, const Eigen::Vector2d& x) {
  return std::abs(line.dot(x.homogeneous())) / line.head<2>().norm();
}

int Main(int argc, char** argv) {
  std::string workdir;
  double max_epipolar_px = 4.0;
  bool list_pairs = false;
  for (int a = 1; a < argc; ++a) {
    const std::string key = argv[a];
    if (key == "--pairs") {
      list_pairs = true;
    } else if (a + 1 < argc && key == "--workdir") {
      workdir = argv[++a];
    } else if (a + 1 < argc && key == "--max-epipolar-px") {
      max_epipolar_px = std::stod(argv[++a]);
    } else {
      throw InputError(
          "usage: match_quality --workdir DIR [--max-epipolar-px 4] [--pairs] "
          "(unknown or incomplete argument '" +
          key + "')");
    }
  }
  if (workdir.empty()) throw InputError("match_quality: --workdir is required");
  const Hdf5Reader dataset((fs::path(workdir) / "dataset.h5").string());
  const ImageSet images = dataset.ReadImages();
  const PoseSet truth = dataset.ReadPoseSet("ground_truth");
  const std::vector<ImageFeatures> features =
      Hdf5Reader((fs::path(workdir) / "features.h5").string()).ReadFeatures();
  const std::vector<PairMatches> pairs =
      Hdf5Reader((fs::path(workdir) / "matches.h5").string()).ReadMatches();

  std::vector<double> rotation_errors;
  int wrong = 0;
  int64_t inliers = 0, far_inliers = 0;
  for (const PairMatches& pair : pairs) {
    const ImageInfo& image1 = images.images.at(pair.image1);
    const ImageInfo& image2 = images.images.at(pair.image2);
    const CameraIntrinsics& camera1 = images.cameras.at(image1.camera_index);
    const CameraIntrinsics& camera2 = images.cameras.at(image2.camera_index);
    const Rigid3 cam2_from_cam1 =
        truth.world_from_cam.at(image2.name).Inverse() * truth.world_from_cam.at(image1.name);
    const Eigen::Matrix3d F = InversePinhole(camera2).transpose() *
                              Skew(cam2_from_cam1.translation) * cam2_from_cam1.RotationMatrix() *
                              InversePinhole(camera1);
    std::vector<double> distances;
    const auto& m = pair.geometry.inlier_matches;
    for (Eigen::Index k = 0; k < m.rows(); ++k) {
      const Eigen::Vector2d x1 = Undistorted(camera1, features[pair.image1], m(k, 0));
      const Eigen::Vector2d x2 = Undistorted(camera2, features[pair.image2], m(k, 1));
      distances.push_back(0.5 * (LineDistance(F * x1.homogeneous(), x2) +
                                 LineDistance(F.transpose() * x2.homogeneous(), x1)));
      far_inliers += distances.back() > 10.0;
    }
    inliers += m.rows();
    const double median_px = Percentile(distances, 0.5);
    const bool is_wrong = median_px > max_epipolar_px;
    wrong += is_wrong;
    double rotation_deg = std::nan("");
    if (pair.geometry.config == TwoViewConfig::kCalibrated) {
      rotation_deg = DegreesFromRadians(
          RotationDistance(pair.geometry.cam2_from_cam1.rotation, cam2_from_cam1.rotation));
      rotation_errors.push_back(rotation_deg);
    }
    if (list_pairs || is_wrong) {
      std::printf(
          "pair %s-%s: %ld inliers, rotation error %.3f deg, median epipolar error %.2f "
          "px%s\n",
          image1.name.c_str(), image2.name.c_str(), static_cast<long>(m.rows()), rotation_deg,
          median_px, is_wrong ? "  WRONG" : "");
    }
  }
  std::printf(
      "%s: %zu verified pairs, %ld inliers; relative rotation error median %.3f deg, "
      "p90 %.3f deg (%zu calibrated pairs); %d wrong pairs (median epipolar error > %.1f "
      "px); %.2f %% of inliers > 10 px\n",
      workdir.c_str(), pairs.size(), static_cast<long>(inliers), Percentile(rotation_errors, 0.5),
      Percentile(rotation_errors, 0.9), rotation_errors.size(), wrong, max_epipolar_px,
      inliers > 0 ? 100.0 * far_inliers / inliers : 0.0);
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  return raytime::BenchMain("match_quality", raytime::Main, argc, argv);
}
