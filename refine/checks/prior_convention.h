// Is the prior in the convention its reader assumed? A check before refining (issue 30): the
// verified pairs' own relative poses (the front end's essential matrices, estimated without any
// prior) are compared with those of the prior read as given and under each other convention
// (core/geometry.h PoseConvention). A prior given camera-to-world where world-to-camera was
// expected, or with OpenGL camera axes, explains them no better than chance, and the solve refines
// it into a wrong answer that still looks converged (the demo inverted: 84° off, ok_with_warnings);
// the convention that explains them far better is the fix to name.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/geometry.h"

namespace raytime {

// One verified pair's relative pose as the two-view geometry estimated it.
struct MeasuredRelativePose {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix3d cam2_from_cam1_rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d cam2_from_cam1_direction = Eigen::Vector3d::UnitZ();  // unit baseline direction
  // Median angle between the inliers' rays after the rotation is taken out, degrees: below
  // kMinDirectionParallaxDeg the baseline direction is not determined (a near pure rotation).
  double median_parallax_deg = 0.0;
};

// Below this median parallax a pair's baseline direction takes no part in the check.
constexpr double kMinDirectionParallaxDeg = 1.0;

struct ConventionScore {
  std::string convention;  // PoseConventionNames()
  // Medians over the pairs of the angle between measured and prior relative rotation, and over
  // the pairs with parallax of the angle between the baseline directions (NaN: too few pairs).
  double median_rotation_error_deg = 0.0;
  double median_direction_error_deg = 0.0;
  // Rotation plus direction error (the direction's 0 when it is NaN): the check's statistic.
  double score_deg = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ConventionScore, convention, median_rotation_error_deg,
                                   median_direction_error_deg, score_deg)

struct PriorConventionVerdict {
  bool checked = false;  // false: fewer than kMinPairs pairs with a relative pose
  int num_pairs = 0;
  int num_pairs_with_parallax = 0;
  std::vector<ConventionScore> scores;  // one per PoseConvention, native first
  // The convention that explains the matches far better than the prior as given (below), or
  // "native" when none does.
  std::string better_convention = "native";
  bool refused = false;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PriorConventionVerdict, checked, num_pairs,
                                   num_pairs_with_parallax, scores, better_convention, refused)

// The thresholds. An alternative must halve the native score and beat it by 10°: a correct prior
// perturbed by the ladder's 32° scores ~45° per relative rotation, and alternatives near chance
// (~90° and more); a correct prior in the wrong convention scores near chance while the right
// convention scores its own perturbation. Measured on the shared scenes and captures:
// refine/README.md "Prior convention check".
struct PriorConventionCheckOptions {
  int min_pairs = 3;
  double max_score_ratio = 0.5;
  double min_score_gap_deg = 10.0;
  int min_pairs_with_parallax = 3;
};

// `world_from_cam` per image (indexed as the pairs' image indices).
PriorConventionVerdict CheckPriorConvention(const std::vector<Rigid3>& world_from_cam,
                                            const std::vector<MeasuredRelativePose>& pairs,
                                            const PriorConventionCheckOptions& options = {});

// Median angle, degrees, between rays1.row(k) rotated into camera 2 and rays2.row(k) (unit rays,
// one inlier correspondence per row): the parallax left after the rotation is taken out.
double MedianParallaxDeg(const Eigen::Matrix3d& cam2_from_cam1_rotation,
                         const Eigen::Matrix<double, Eigen::Dynamic, 3>& rays1,
                         const Eigen::Matrix<double, Eigen::Dynamic, 3>& rays2);

// The refusal's text: what the scores say and the option that fixes it (`option`, e.g.
// "prior.convention").
std::string DescribeConventionRefusal(const PriorConventionVerdict& verdict,
                                      const std::string& option);

}  // namespace raytime
