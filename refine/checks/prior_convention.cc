#include "refine/checks/prior_convention.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/statistics.h"

namespace raytime {
namespace {

double ConventionAngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return DegreesFromRadians(std::atan2(a.cross(b).norm(), a.dot(b)));
}

ConventionScore ScoreOfConvention(const std::vector<Rigid3>& world_from_cam,
                                  const std::vector<MeasuredRelativePose>& pairs,
                                  PoseConvention convention, int min_pairs_with_parallax) {
  std::vector<Rigid3> poses;
  poses.reserve(world_from_cam.size());
  for (const Rigid3& pose : world_from_cam) poses.push_back(ApplyPoseConvention(pose, convention));
  std::vector<double> rotation_errors, direction_errors;
  for (const MeasuredRelativePose& pair : pairs) {
    const Rigid3 cam2_from_cam1 = poses.at(pair.image2).Inverse() * poses.at(pair.image1);
    rotation_errors.push_back(DegreesFromRadians(RotationAngle(Eigen::Matrix3d(
        pair.cam2_from_cam1_rotation.transpose() * cam2_from_cam1.RotationMatrix()))));
    if (pair.median_parallax_deg < kMinDirectionParallaxDeg) continue;
    const Eigen::Vector3d& baseline = cam2_from_cam1.translation;
    if (!(baseline.norm() > 0)) continue;
    direction_errors.push_back(ConventionAngleDeg(baseline, pair.cam2_from_cam1_direction));
  }
  ConventionScore score;
  score.convention = PoseConventionName(convention);
  score.median_rotation_error_deg = Median(rotation_errors, 0.0);
  score.median_direction_error_deg =
      static_cast<int>(direction_errors.size()) >= min_pairs_with_parallax
          ? Median(direction_errors, 0.0)
          : std::numeric_limits<double>::quiet_NaN();
  score.score_deg =
      score.median_rotation_error_deg +
      (std::isnan(score.median_direction_error_deg) ? 0.0 : score.median_direction_error_deg);
  return score;
}

}  // namespace

PriorConventionVerdict CheckPriorConvention(const std::vector<Rigid3>& world_from_cam,
                                            const std::vector<MeasuredRelativePose>& pairs,
                                            const PriorConventionCheckOptions& options) {
  PriorConventionVerdict verdict;
  verdict.num_pairs = static_cast<int>(pairs.size());
  for (const MeasuredRelativePose& pair : pairs) {
    if (pair.median_parallax_deg >= kMinDirectionParallaxDeg) ++verdict.num_pairs_with_parallax;
  }
  if (verdict.num_pairs < options.min_pairs) return verdict;
  verdict.checked = true;
  // Direction errors count only where every convention has enough of them, so that the scores
  // are sums of the same terms.
  const int min_parallax = verdict.num_pairs_with_parallax >= options.min_pairs_with_parallax
                               ? options.min_pairs_with_parallax
                               : std::numeric_limits<int>::max();
  for (size_t c = 0; c < PoseConventionNames().size(); ++c) {
    verdict.scores.push_back(
        ScoreOfConvention(world_from_cam, pairs, static_cast<PoseConvention>(c), min_parallax));
  }
  const ConventionScore& native = verdict.scores.front();
  const auto best = std::min_element(
      verdict.scores.begin() + 1, verdict.scores.end(),
      [](const ConventionScore& a, const ConventionScore& b) { return a.score_deg < b.score_deg; });
  if (best->score_deg <= options.max_score_ratio * native.score_deg &&
      native.score_deg - best->score_deg >= options.min_score_gap_deg) {
    verdict.refused = true;
    verdict.better_convention = best->convention;
  }
  return verdict;
}

double MedianParallaxDeg(const Eigen::Matrix3d& cam2_from_cam1_rotation,
                         const Eigen::Matrix<double, Eigen::Dynamic, 3>& rays1,
                         const Eigen::Matrix<double, Eigen::Dynamic, 3>& rays2) {
  std::vector<double> angles;
  angles.reserve(static_cast<size_t>(rays1.rows()));
  for (Eigen::Index k = 0; k < rays1.rows(); ++k) {
    angles.push_back(ConventionAngleDeg(cam2_from_cam1_rotation * rays1.row(k).transpose(),
                                        rays2.row(k).transpose()));
  }
  return Median(angles, 0.0);
}

std::string DescribeConventionRefusal(const PriorConventionVerdict& verdict,
                                      const std::string& option) {
  const auto find = [&](const std::string& name) -> const ConventionScore& {
    return *std::find_if(verdict.scores.begin(), verdict.scores.end(),
                         [&](const ConventionScore& s) { return s.convention == name; });
  };
  const auto describe = [](const ConventionScore& s) {
    std::string text = fmt::format("{:.1f}° in rotation", s.median_rotation_error_deg);
    if (!std::isnan(s.median_direction_error_deg)) {
      text += fmt::format(", {:.1f}° in baseline direction", s.median_direction_error_deg);
    }
    return text;
  };
  const ConventionScore& native = verdict.scores.front();
  const ConventionScore& better = find(verdict.better_convention);
  std::string looks;
  if (verdict.better_convention == "inverted") {
    looks = "camera-to-world poses given where world-to-camera ones were expected, or the reverse";
  } else if (verdict.better_convention == "flipped_axes") {
    looks =
        "camera axes in the OpenGL convention (y up, z backwards) where OpenCV's (y down, z "
        "forwards) were expected, or the reverse";
  } else {
    looks =
        "poses both inverted (camera-to-world for world-to-camera, or the reverse) and in "
        "the other camera-axis convention (OpenGL for OpenCV, or the reverse)";
  }
  return fmt::format(
      "the prior disagrees with the matches' own relative poses (median over {} verified pairs: "
      "{}), while the same poses {} agree with them ({}): the prior looks like {}. Set {}={} to "
      "read it so",
      verdict.num_pairs, describe(native),
      verdict.better_convention == "inverted"       ? "inverted"
      : verdict.better_convention == "flipped_axes" ? "with flipped camera axes"
                                                    : "inverted and with flipped camera axes",
      describe(better), looks, option, verdict.better_convention);
}

}  // namespace raytime
