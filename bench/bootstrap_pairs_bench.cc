// Scores a bootstrap run against ground truth (issue 5 "Must show"): rotation error of the pose
// set "bootstrap", and precision / recall of the wrong-pair detector, where a verified pair is
// wrong when the median symmetric epipolar distance of its inliers under the ground-truth poses
// exceeds --threshold-px (the data README's labelling of castle-P19: 88 of 169 wrong at 4 px).
//
// This tool lives outside bootstrap/ on purpose: the bootstrap must never see ground truth.
//
//   bootstrap_pairs_bench --dataset W/dataset.h5 --matches W/matches.h5
//       --bootstrap W/bootstrap.h5 [--features FILE] [--threshold-px 4] [--pairs] [--json OUT]
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include "bench/bench_main.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/statistics.h"
#include "evaluate/pose_errors.h"

namespace raytime {
namespace {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d CalibrationMatrix(const CameraIntrinsics& camera) {
  Eigen::Matrix3d k;
  k << camera.fx(), 0, camera.cx(), 0, camera.fy(), camera.cy(), 0, 0, 1;
  return k;
}

Eigen::Vector3d Undistorted(const CameraIntrinsics& camera, const ImageFeatures& features,
                            uint32_t row) {
  const double distorted[2] = {features.keypoints(row, 0), features.keypoints(row, 1)};
  double u[2];
  UndistortPixel(camera.params.data(), distorted, u);
  return Eigen::Vector3d(u[0], u[1], 1.0);
}

// Median over inliers of the mean of the two point-to-epipolar-line distances (pixels).
double MedianEpipolarError(const ImageSet& images, const PoseSet& truth,
                           const std::vector<ImageFeatures>& features, const PairMatches& pair) {
  const ImageInfo& info1 = images.images[pair.image1];
  const ImageInfo& info2 = images.images[pair.image2];
  const CameraIntrinsics& camera1 = images.cameras[info1.camera_index];
  const CameraIntrinsics& camera2 = images.cameras[info2.camera_index];
  const Rigid3& pose1 = truth.world_from_cam.at(info1.name);
  const Rigid3& pose2 = truth.world_from_cam.at(info2.name);
  const Eigen::Matrix3d r21 = pose2.RotationMatrix().transpose() * pose1.RotationMatrix();
  const Eigen::Vector3d t21 =
      pose2.RotationMatrix().transpose() * (pose1.translation - pose2.translation);
  const Eigen::Matrix3d f = CalibrationMatrix(camera2).inverse().transpose() * Skew(t21) * r21 *
                            CalibrationMatrix(camera1).inverse();
  std::vector<double> errors;
  const auto& m = pair.geometry.inlier_matches;
  for (Eigen::Index k = 0; k < m.rows(); ++k) {
    const Eigen::Vector3d x1 = Undistorted(camera1, features[pair.image1], m(k, 0));
    const Eigen::Vector3d x2 = Undistorted(camera2, features[pair.image2], m(k, 1));
    const Eigen::Vector3d line2 = f * x1, line1 = f.transpose() * x2;
    const double algebraic = std::abs(x2.dot(f * x1));
    errors.push_back(0.5 *
                     (algebraic / line2.head<2>().norm() + algebraic / line1.head<2>().norm()));
  }
  return UpperMedian(errors, 0.0);
}

int Run(int argc, char** argv) {
  CLI::App app("Score the bootstrap's poses and wrong-pair verdicts against ground truth");
  std::string dataset_path, matches_path, features_path, bootstrap_path, json_path;
  double threshold_px = 4.0;
  bool list_pairs = false;
  app.add_option("--dataset", dataset_path, "HDF5 with /images and the ground-truth poses")
      ->required();
  app.add_option("--matches", matches_path, "HDF5 with the verified matches")->required();
  app.add_option("--features", features_path, "HDF5 with the keypoints (default: --matches)");
  app.add_option("--bootstrap", bootstrap_path, "HDF5 written by the bootstrap stage")->required();
  app.add_option("--threshold-px", threshold_px, "Ground-truth labelling threshold, pixels")
      ->capture_default_str();
  app.add_flag("--pairs", list_pairs, "Print one line per pair");
  app.add_option("--json", json_path, "Write the numbers as JSON");
  CLI11_PARSE(app, argc, argv);
  if (features_path.empty()) features_path = matches_path;

  const Hdf5Reader dataset(dataset_path);
  const ImageSet images = dataset.ReadImages();
  const PoseSet truth = dataset.ReadPoseSet("ground_truth");
  const std::vector<ImageFeatures> features = Hdf5Reader(features_path).ReadFeatures();
  const std::vector<PairMatches> matches = Hdf5Reader(matches_path).ReadMatches();
  const Hdf5Reader bootstrap(bootstrap_path);
  const PoseSet poses = bootstrap.ReadPoseSet("bootstrap");
  const nlohmann::json verdicts = bootstrap.ReadJson("bootstrap_pairs");

  std::map<std::pair<std::string, std::string>, nlohmann::json> verdict_of;
  for (const auto& entry : verdicts) {
    verdict_of[{entry.at("image1").get<std::string>(), entry.at("image2").get<std::string>()}] =
        entry;
  }
  int pairs = 0, truly_wrong = 0, flagged = 0, true_positive = 0, unusable = 0;
  int wrong_unusable = 0;
  if (list_pairs) {
    std::printf("%-10s %-10s %7s %9s %5s %-8s %7s %7s %7s %5s\n", "image1", "image2", "inliers",
                "epi_px", "gt", "verdict", "score", "rot_deg", "dir_deg", "cyc");
  }
  for (const auto& pair : matches) {
    if (pair.geometry.inlier_matches.rows() == 0) continue;
    ++pairs;
    const std::string& name1 = images.images[pair.image1].name;
    const std::string& name2 = images.images[pair.image2].name;
    const double error = MedianEpipolarError(images, truth, features, pair);
    const bool wrong = error > threshold_px;
    truly_wrong += wrong;
    const auto it = verdict_of.find({name1, name2});
    const std::string verdict =
        it == verdict_of.end() ? "missing" : it->second.at("verdict").get<std::string>();
    if (verdict == "wrong") {
      ++flagged;
      true_positive += wrong;
    } else if (verdict != "kept") {
      ++unusable;
      wrong_unusable += wrong;
    }
    if (list_pairs) {
      auto number = [&](const char* key) {
        return it == verdict_of.end() || it->second.at(key).is_null()
                   ? NAN
                   : it->second.at(key).get<double>();
      };
      std::printf("%-10s %-10s %7ld %9.2f %5s %-8s %7.2f %7.2f %7.2f %2d/%-2d\n", name1.c_str(),
                  name2.c_str(), static_cast<long>(pair.geometry.inlier_matches.rows()), error,
                  wrong ? "WRONG" : "ok", verdict.c_str(), number("score"),
                  number("rotation_residual_deg"), number("direction_residual_deg"),
                  it == verdict_of.end() ? 0 : it->second.at("cycle_consistent").get<int>(),
                  it == verdict_of.end() ? 0 : it->second.at("cycle_triplets").get<int>());
    }
  }
  const int false_positive = flagged - true_positive;
  const int correct = pairs - truly_wrong;
  const double precision = flagged ? static_cast<double>(true_positive) / flagged : 1.0;
  const double recall = truly_wrong ? static_cast<double>(true_positive) / truly_wrong : 1.0;

  PoseErrorOptions error_options;
  const PoseErrorSummary errors = ComputePoseErrors(poses, truth, error_options);
  std::printf(
      "pairs %d, wrong under ground truth (> %.1f px) %d, unusable for the bootstrap %d "
      "(%d of them wrong)\n",
      pairs, threshold_px, truly_wrong, unusable, wrong_unusable);
  std::printf(
      "detector: flagged %d, true positives %d, false positives %d (correct pairs lost: "
      "%d of %d), precision %.3f, recall %.3f\n",
      flagged, true_positive, false_positive, false_positive, correct, precision, recall);
  std::printf(
      "bootstrap poses: %d of %zu images, rotation error mean %.3f° median %.3f° "
      "(Sim(3)), centre error mean %.3f m\n",
      errors.num_frames, images.images.size(), errors.mean_rotation_deg, errors.median_rotation_deg,
      errors.mean_centre_m);
  if (!json_path.empty()) {
    const nlohmann::json out = {{"pairs", pairs},
                                {"threshold_px", threshold_px},
                                {"truly_wrong", truly_wrong},
                                {"unusable", unusable},
                                {"flagged", flagged},
                                {"true_positive", true_positive},
                                {"false_positive", false_positive},
                                {"precision", precision},
                                {"recall", recall},
                                {"rotation", errors.ToJson(false)}};
    std::ofstream(json_path) << out.dump(2) << "\n";
  }
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  return raytime::BenchMain("bootstrap_pairs_bench", raytime::Run, argc, argv);
}
