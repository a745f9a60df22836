#include "bootstrap/view_graph_builder.h"

#include <tbb/parallel_for.h>

#include <stdexcept>
#include <string>

#include "core/camera.h"
#include "core/error.h"

namespace raytime {
namespace {

std::string PairName(const PairMatches& pair) {
  return "pair " + std::to_string(pair.image1) + "_" + std::to_string(pair.image2);
}

Eigen::Vector2d Keypoint(const ImageFeatures& features, uint32_t row) {
  return Eigen::Vector2d(features.keypoints(row, 0), features.keypoints(row, 1));
}

Eigen::Vector3d Bearing(const CameraIntrinsics& camera, const Eigen::Vector2d& pixel) {
  Eigen::Vector3d ray;
  ObservedPixelToUnitRay(camera.params.data(), pixel.data(), ray.data());
  return ray;
}

void CheckInput(const ImageSet& images, const std::vector<ImageFeatures>& features,
                const std::vector<PairMatches>& matches) {
  const int n = static_cast<int>(images.images.size());
  if (static_cast<int>(features.size()) != n) {
    throw InputError("features cover " + std::to_string(features.size()) +
                     " images, the image list has " + std::to_string(n));
  }
  for (const auto& image : images.images) {
    if (image.camera_index < 0 || image.camera_index >= static_cast<int>(images.cameras.size())) {
      throw InputError("image " + image.name + " has no camera " +
                       std::to_string(image.camera_index));
    }
  }
  for (const auto& pair : matches) {
    if (pair.image1 < 0 || pair.image2 < 0 || pair.image1 >= n || pair.image2 >= n ||
        pair.image1 >= pair.image2) {
      throw InputError(PairName(pair) +
                       ": image indices must satisfy 0 <= image1 < "
                       "image2 < " +
                       std::to_string(n));
    }
    const auto& m = pair.geometry.inlier_matches;
    const Eigen::Index rows1 = features[pair.image1].keypoints.rows();
    const Eigen::Index rows2 = features[pair.image2].keypoints.rows();
    for (Eigen::Index k = 0; k < m.rows(); ++k) {
      if (m(k, 0) >= rows1 || m(k, 1) >= rows2) {
        throw InputError(PairName(pair) + ": inlier match " + std::to_string(k) +
                         " refers to keypoint (" + std::to_string(m(k, 0)) + ", " +
                         std::to_string(m(k, 1)) + ") but the images have " +
                         std::to_string(rows1) + " and " + std::to_string(rows2) + " keypoints");
      }
    }
  }
}

}  // namespace

ViewGraphBuildResult BuildViewGraph(const ImageSet& images,
                                    const std::vector<ImageFeatures>& features,
                                    const std::vector<PairMatches>& matches,
                                    const RelativePoseOptions& relative_pose, bool focal_search,
                                    const FocalSearchOptions& focal_options) {
  ValidateOptions(relative_pose, "relative pose");
  CheckInput(images, features, matches);
  ViewGraphBuildResult result;
  result.cameras = images.cameras;
  result.num_pairs_input = static_cast<int>(matches.size());

  std::vector<const PairMatches*> pairs;
  for (const auto& pair : matches) {
    if (pair.geometry.inlier_matches.rows() > 0) pairs.push_back(&pair);
  }

  if (focal_search) {
    for (size_t c = 0; c < result.cameras.size(); ++c) {
      std::vector<PixelCorrespondences> correspondences;
      for (const PairMatches* pair : pairs) {
        if (images.images[pair->image1].camera_index != static_cast<int>(c) ||
            images.images[pair->image2].camera_index != static_cast<int>(c)) {
          continue;
        }
        const auto& m = pair->geometry.inlier_matches;
        PixelCorrespondences pc;
        pc.pixels1.resize(2, m.rows());
        pc.pixels2.resize(2, m.rows());
        for (Eigen::Index k = 0; k < m.rows(); ++k) {
          pc.pixels1.col(k) = Keypoint(features[pair->image1], m(k, 0));
          pc.pixels2.col(k) = Keypoint(features[pair->image2], m(k, 1));
        }
        correspondences.push_back(std::move(pc));
      }
      CameraIntrinsics& camera = result.cameras[c];
      if (camera.width <= 0 || camera.height <= 0) {
        throw InputError("focal search: camera " + std::to_string(c) + " has no image size");
      }
      const FocalSearchResult search =
          SearchFocal(correspondences, camera.width, camera.height, focal_options, relative_pose);
      camera.params = {search.focal_px,
                       search.focal_px,
                       (camera.width - 1) / 2.0,
                       (camera.height - 1) / 2.0,
                       0,
                       0,
                       0,
                       0};
      result.focal_searches.push_back(search);
    }
  }
  for (const auto& camera : result.cameras) {
    if (!(camera.fx() > 0) || !(camera.fy() > 0)) {
      throw InputError(
          "a camera has no focal length; enable the focal search (bootstrap.focal_search)");
    }
  }

  result.edges.resize(pairs.size());
  tbb::parallel_for(size_t(0), pairs.size(), [&](size_t p) {
    const PairMatches& pair = *pairs[p];
    const CameraIntrinsics& camera1 = result.cameras[images.images[pair.image1].camera_index];
    const CameraIntrinsics& camera2 = result.cameras[images.images[pair.image2].camera_index];
    const auto& m = pair.geometry.inlier_matches;
    Eigen::Matrix3Xd bearings1(3, m.rows()), bearings2(3, m.rows());
    for (Eigen::Index k = 0; k < m.rows(); ++k) {
      bearings1.col(k) = Bearing(camera1, Keypoint(features[pair.image1], m(k, 0)));
      bearings2.col(k) = Bearing(camera2, Keypoint(features[pair.image2], m(k, 1)));
    }
    const double focal = (camera1.fx() + camera1.fy() + camera2.fx() + camera2.fy()) / 4.0;
    const RelativePoseResult pose =
        EstimateRelativePose(bearings1, bearings2, focal, relative_pose);
    ViewGraphEdge& edge = result.edges[p];
    edge.image1 = pair.image1;
    edge.image2 = pair.image2;
    edge.rotation = pose.rotation;
    edge.translation = pose.translation;
    edge.num_correspondences = static_cast<int>(m.rows());
    edge.num_inliers = static_cast<int>(pose.inliers.size());
    edge.median_parallax_deg = pose.median_parallax_deg;
    edge.status = pose.status;
  });
  return result;
}

}  // namespace raytime
