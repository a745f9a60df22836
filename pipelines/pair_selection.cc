#include "pipelines/pair_selection.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <numeric>
#include <set>
#include <string>

#include "core/statistics.h"
#include "core/timing.h"

namespace raytime {
namespace {

// Overlap samples: a grid over the image (cell centres) at three depths per sample.
constexpr int kGridColumns = 8;
constexpr int kGridRows = 6;
constexpr double kDepthFactors[] = {0.5, 1.0, 2.0};
// Optical axes closer than this in angle carry no usable closest-approach depth (it diverges as
// the axes become parallel).
constexpr double kMinAxisAngleDeg = 2.0;

Eigen::Vector3d OpticalAxis(const PairSelectionView& view) {
  return view.world_from_cam_rotation.col(2);
}

double AxisAngleDeg(const PairSelectionView& a, const PairSelectionView& b) {
  const Eigen::Vector3d za = OpticalAxis(a), zb = OpticalAxis(b);
  return std::atan2(za.cross(zb).norm(), za.dot(zb)) * 180.0 / M_PI;
}

// `from`'s samples (grid x depths, at scene depth `depth`) that `to` sees, each weighted by how
// little the viewpoint changes at it, as a fraction of all samples.
double SeenFraction(const PairSelectionView& from, double depth, const PairSelectionView& to,
                    double max_scale_ratio, double max_angle_deg) {
  const Eigen::Matrix3d to_from_world = to.world_from_cam_rotation.transpose();
  const double max_angle = max_angle_deg * M_PI / 180.0;
  double seen = 0;
  int total = 0;
  for (int r = 0; r < kGridRows; ++r) {
    for (int c = 0; c < kGridColumns; ++c) {
      // Cell centres of the image, in the OpenCV pixel convention.
      const double u = (c + 0.5) * from.width / kGridColumns - 0.5;
      const double v = (r + 0.5) * from.height / kGridRows - 0.5;
      const Eigen::Vector3d ray((u - from.cx) / from.fx, (v - from.cy) / from.fy, 1.0);
      for (const double factor : kDepthFactors) {
        ++total;
        const double z_from = factor * depth;
        const Eigen::Vector3d point = from.centre + from.world_from_cam_rotation * (z_from * ray);
        const Eigen::Vector3d in_to = to_from_world * (point - to.centre);
        if (!(in_to.z() > 0)) continue;
        const double x = to.fx * in_to.x() / in_to.z() + to.cx;
        const double y = to.fy * in_to.y() / in_to.z() + to.cy;
        if (x < -0.5 || x > to.width - 0.5 || y < -0.5 || y > to.height - 0.5) continue;
        // Pixels per unit length at the point in each view.
        const double scale = (to.fx / in_to.z()) / (from.fx / z_from);
        if (scale > max_scale_ratio || scale * max_scale_ratio < 1.0) continue;
        // Angle between the two viewing rays at the point: the viewpoint change SIFT must bridge.
        const Eigen::Vector3d ray_from = point - from.centre, ray_to = point - to.centre;
        const double angle = std::atan2(ray_from.cross(ray_to).norm(), ray_from.dot(ray_to));
        seen += std::max(0.0, 1.0 - angle / max_angle);
      }
    }
  }
  return total > 0 ? seen / total : 0.0;
}

}  // namespace

nlohmann::json PairSelectionSummary::ToJson() const { return *this; }

double ViewOverlap(const PairSelectionView& a, double depth_a, const PairSelectionView& b,
                   double depth_b, double max_scale_ratio, double max_angle_deg) {
  return 0.5 * (SeenFraction(a, depth_a, b, max_scale_ratio, max_angle_deg) +
                SeenFraction(b, depth_b, a, max_scale_ratio, max_angle_deg));
}

std::vector<double> SceneDepths(const std::vector<PairSelectionView>& views, double given,
                                std::string* source) {
  const int n = static_cast<int>(views.size());
  std::vector<double> depths(n, 0.0);
  if (given > 0) {
    for (int i = 0; i < n; ++i) depths[i] = views[i].has_pose ? given : 0.0;
    if (source) *source = "given";
    return depths;
  }
  const double min_sin = std::sin(kMinAxisAngleDeg * M_PI / 180.0);
  std::vector<std::vector<double>> samples(n);
  std::vector<double> all;
  for (int i = 0; i < n; ++i) {
    if (!views[i].has_pose) continue;
    for (int j = i + 1; j < n; ++j) {
      if (!views[j].has_pose) continue;
      // Closest approach of C_i + s z_i and C_j + t z_j (unit axes).
      const Eigen::Vector3d zi = OpticalAxis(views[i]), zj = OpticalAxis(views[j]);
      const double b = zi.dot(zj);
      const double denom = 1.0 - b * b;
      if (denom < min_sin * min_sin) continue;
      const Eigen::Vector3d w = views[i].centre - views[j].centre;
      const double d = zi.dot(w), e = zj.dot(w);
      const double s = (b * e - d) / denom;
      const double t = (e - b * d) / denom;
      if (!(s > 0 && t > 0)) continue;
      samples[i].push_back(s);
      samples[j].push_back(t);
      all.push_back(s);
      all.push_back(t);
    }
  }
  double fallback = UpperMedian(all, 0.0);
  if (source) *source = "axes";
  if (!(fallback > 0)) {
    // No converging axes: the capture's own extent.
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    int posed = 0;
    for (const auto& view : views) {
      if (!view.has_pose) continue;
      centroid += view.centre;
      ++posed;
    }
    if (posed > 0) centroid /= posed;
    std::vector<double> distances;
    for (const auto& view : views) {
      if (view.has_pose) distances.push_back((view.centre - centroid).norm());
    }
    fallback = Median(distances, 0.0);
    // All centres at one point (a pure rotation): overlap does not depend on depth.
    if (!(fallback > 0)) fallback = 1.0;
    if (source) *source = "extent";
  }
  for (int i = 0; i < n; ++i) {
    if (views[i].has_pose) depths[i] = UpperMedian(samples[i], fallback);
  }
  return depths;
}

std::vector<PairSelectionView> PairSelectionViews(const ImageSet& images, const PoseSet& poses) {
  std::vector<PairSelectionView> views(images.images.size());
  std::vector<int> order(images.images.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return NaturalNameLess(images.images[a].name, images.images[b].name);
  });
  for (size_t s = 0; s < order.size(); ++s) views[order[s]].sequence = static_cast<int>(s);
  for (size_t i = 0; i < images.images.size(); ++i) {
    const ImageInfo& info = images.images[i];
    const CameraIntrinsics& camera = images.cameras.at(info.camera_index);
    PairSelectionView& view = views[i];
    view.fx = camera.fx();
    view.fy = camera.fy();
    view.cx = camera.cx();
    view.cy = camera.cy();
    view.width = info.width > 0 ? info.width : camera.width;
    view.height = info.height > 0 ? info.height : camera.height;
    const auto pose = poses.world_from_cam.find(info.name);
    // Without a pose or a focal length the view cannot be placed: window pairs only.
    if (pose == poses.world_from_cam.end() || !(view.fx > 0 && view.fy > 0) || view.width <= 0 ||
        view.height <= 0) {
      continue;
    }
    view.has_pose = true;
    view.world_from_cam_rotation = pose->second.RotationMatrix();
    view.centre = pose->second.translation;
  }
  return views;
}

std::vector<std::pair<int, int>> SelectPriorPairs(const std::vector<PairSelectionView>& views,
                                                  const PriorPairOptions& options,
                                                  PairSelectionSummary* summary) {
  ValidateOptions(options, "prior pair selection");
  const auto start = std::chrono::steady_clock::now();
  const int n = static_cast<int>(views.size());
  PairSelectionSummary local;
  PairSelectionSummary& out = summary ? *summary : local;
  out = PairSelectionSummary();
  out.num_images = n;
  out.num_exhaustive_pairs = static_cast<int64_t>(n) * (n - 1) / 2;
  const std::vector<double> depths =
      SceneDepths(views, options.prior_scene_depth, &out.scene_depth_source);

  // Candidates of every posed image: (overlap, centre distance, partner).
  struct Candidate {
    double overlap, distance;
    int partner;
  };
  std::vector<std::vector<Candidate>> candidates(n);
  for (int i = 0; i < n; ++i) {
    if (!views[i].has_pose) continue;
    for (int j = i + 1; j < n; ++j) {
      if (!views[j].has_pose) continue;
      if (AxisAngleDeg(views[i], views[j]) > options.prior_max_angle_deg) continue;
      const double overlap =
          ViewOverlap(views[i], depths[i], views[j], depths[j], options.prior_max_scale_ratio,
                      options.prior_max_angle_deg);
      if (!(overlap > 0) || overlap < options.prior_min_overlap) continue;
      const double distance = (views[i].centre - views[j].centre).norm();
      candidates[i].push_back({overlap, distance, j});
      candidates[j].push_back({overlap, distance, i});
    }
  }
  std::set<std::pair<int, int>> chosen;
  for (int i = 0; i < n; ++i) {
    std::vector<Candidate>& list = candidates[i];
    std::sort(list.begin(), list.end(), [](const Candidate& a, const Candidate& b) {
      if (a.overlap != b.overlap) return a.overlap > b.overlap;
      if (a.distance != b.distance) return a.distance < b.distance;
      return a.partner < b.partner;
    });
    const size_t keep = std::min(list.size(), static_cast<size_t>(options.prior_neighbors));
    for (size_t k = 0; k < keep; ++k) {
      chosen.insert({std::min(i, list[k].partner), std::max(i, list[k].partner)});
    }
  }
  out.num_overlap_pairs = static_cast<int64_t>(chosen.size());
  std::vector<int> by_sequence(n);
  std::iota(by_sequence.begin(), by_sequence.end(), 0);
  std::stable_sort(by_sequence.begin(), by_sequence.end(),
                   [&](int a, int b) { return views[a].sequence < views[b].sequence; });
  for (int s = 0; s < n; ++s) {
    for (int t = s + 1; t <= std::min(n - 1, s + options.prior_window); ++t) {
      const int i = std::min(by_sequence[s], by_sequence[t]);
      const int j = std::max(by_sequence[s], by_sequence[t]);
      if (chosen.insert({i, j}).second) ++out.num_window_pairs;
    }
  }
  const std::vector<std::pair<int, int>> pairs(chosen.begin(), chosen.end());
  out.num_pairs = static_cast<int64_t>(pairs.size());

  std::vector<int> partners(n, 0);
  for (const auto& [i, j] : pairs) {
    ++partners[i];
    ++partners[j];
  }
  std::vector<double> posed_partners, posed_depths;
  for (int i = 0; i < n; ++i) {
    if (!views[i].has_pose) continue;
    ++out.num_images_with_pose;
    posed_partners.push_back(partners[i]);
    posed_depths.push_back(depths[i]);
    if (partners[i] == 0) out.unpaired_images.push_back(i);
  }
  if (!posed_partners.empty()) {
    out.min_partners =
        static_cast<int>(*std::min_element(posed_partners.begin(), posed_partners.end()));
    out.max_partners =
        static_cast<int>(*std::max_element(posed_partners.begin(), posed_partners.end()));
  }
  out.median_partners = Median(posed_partners, 0.0);
  out.median_scene_depth = Median(posed_depths, 0.0);
  out.seconds = SecondsSince(start);
  return pairs;
}

}  // namespace raytime
