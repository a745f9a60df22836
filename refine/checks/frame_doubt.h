// Per-frame doubt about a returned solve (issue 30 item 3; beyond the paper, cf. its §4.11
// "Failure analysis"). The pair tests (guardrails.h) see a frame only through its pairs' epipolar
// geometry, which a frame with wrong intrinsics keeps nearly intact by moving: fountain-P11 with
// one focal length 1.5x moved that camera 3.5 m (the others 0.5 m) with every pair consistent. Two
// signs together name such a frame:
// - its correction stands out: after a Sim(3) fit of the solution's centres onto the prior's, its
//   centre moved more than `centre_change_factor` x the median frame's, and more than
//   `min_centre_change_fraction` of the prior's extent (a phone prior is good to centimetres, a
//   perturbed one moves every frame alike);
// - its matches fit worse than the others': the median over its pairs of the pair's median
//   cross-projection residual at the solve's own ray times (paper eqs. (rij)/(rji)) is more than
//   `residual_ratio` x the median over all pairs. Either alone is not enough: a phone's tracking
//   glitch that the solve fixed moves one frame far and fits well; an end frame seen obliquely fits
//   worse and moves like the others. Only a frame that fits `far_residual_ratio` x worse is
//   doubted for that alone.
// Plain Eigen: the solve's observations, ray times and matches (SolvedObservations), its poses and
// per-image intrinsics.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "core/options.h"

namespace raytime {

struct FrameDoubtOptions {
  double centre_change_factor = 5.0;
  double min_centre_change_fraction = 0.02;
  double residual_ratio = 1.25;
  // Alone, whatever its move: a frame whose matches fit this many times worse than the median
  // pair's is not where they are (issue 46: a foreign image matched by a few spurious pairs fitted
  // 34x worse, a focal 1.46x off 21x; the real desk capture's fault-free frames reach 5.2x, its
  // blurred ones).
  double far_residual_ratio = 10.0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("frame_doubt_centre_change_factor", centre_change_factor,
      "A frame is doubted when its centre moved more than this x the median frame's (after a "
      "Sim(3) fit onto the prior) and its matches fit worse than the others'",
      Above(1), AtMost(1e6));
    v("frame_doubt_min_centre_change_fraction", min_centre_change_fraction,
      "... and more than this fraction of the prior's extent (median distance from its centroid)",
      NonNegative(), AtMost(1e6));
    v("frame_doubt_residual_ratio", residual_ratio,
      "... and the median of its pairs' median cross-projection residuals is above this x the "
      "median over all pairs",
      Above(1), AtMost(1e6));
    v("frame_doubt_far_residual_ratio", far_residual_ratio,
      "A frame is doubted however little it moved when its pairs' median cross-projection "
      "residual is above this x the median over all pairs",
      Above(1), AtMost(1e6));
  }
};

struct FrameDoubtVerdict {
  bool checked = false;     // false: fewer than 3 non-collinear centres, or no pair with residuals
  std::vector<int> images;  // doubted frames, ascending
  double median_centre_change = 0.0;
  double centre_change_threshold = 0.0;  // in the prior's length units
  double median_pair_residual_px = 0.0;
  // Per image (the solve's order): centre change after the fit, and its residual ratio (NaN for
  // an image in no pair with residuals).
  std::vector<double> centre_change;
  std::vector<double> residual_ratio;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FrameDoubtVerdict, checked, images, median_centre_change,
                                   centre_change_threshold, median_pair_residual_px, centre_change,
                                   residual_ratio)

// `observation_image(o)` and `observation_pixel.row(o)` (distorted, as observed) of observation
// o, its ray time (NaN: none), and the used matches as rows of observation indices; image i has
// the pose solution[i] (prior[i] before the solve) and the intrinsics intrinsics[i].
FrameDoubtVerdict CheckFrameDoubts(
    const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
    const std::vector<CameraIntrinsics>& intrinsics, const Eigen::VectorXi& observation_image,
    const Eigen::Matrix<double, Eigen::Dynamic, 2>& observation_pixel,
    const Eigen::VectorXd& ray_times,
    const Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>& matches,
    const FrameDoubtOptions& options = {});

}  // namespace raytime
