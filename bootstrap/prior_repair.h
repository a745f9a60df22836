// Gauge fits of bootstrap poses onto a given prior and the two repairs of a coarse prior (SPEC §4;
// paper §4.8 "Basin of convergence": "Replacing the perturbed prior's rotations with
// match-graph-averaged ones [...] and the prior translations kept, recovers 20 of 20 runs at 32°
// [...] and full bootstrap replacement does the same at 64°").
//
// These are the only bootstrap functions that see a prior, and only as an explicit argument: the
// bootstrap itself is computed from the match graph alone.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "core/types.h"

namespace raytime {

// L1 (geodesic median) mean of rotations by Weiszfeld iterations in the tangent space (Hartley
// et al., "L1 rotation averaging using the Weiszfeld algorithm", CVPR 2011), started from the
// chordal mean. Robust to a minority of grossly wrong members. Throws on an empty list.
Eigen::Matrix3d MedianRotation(const std::vector<Eigen::Matrix3d>& rotations);

// Similarity mapping bootstrap centres onto prior centres (Umeyama, with scale), the gauge of a
// bootstrap seed when a prior exists. Throws std::invalid_argument for fewer than 3 pairs or
// collinear centres.
Sim3 FitGaugeToPriorCentres(const std::vector<Eigen::Vector3d>& bootstrap_centres,
                            const std::vector<Eigen::Vector3d>& prior_centres);

struct PriorRepairSummary {
  std::string mode;        // "rotations" or "replace"; "none" when RepairIfCoarse kept the prior
  int num_repaired = 0;    // images whose pose came from the bootstrap
  int num_kept_prior = 0;  // images the bootstrap did not register: prior pose kept
  double scale = 1.0;      // "replace": scale of the Sim(3) gauge fit
  // Median angle between the repaired and the given prior rotations, degrees: how far the
  // prior's rotations are from the match graph's (the gauge rotation taken out).
  double median_rotation_change_deg = 0.0;
  double min_rotation_change_deg = 0.0;  // RepairIfCoarse: the threshold it compared, degrees
};

// Rotations-only repair: every registered image gets its averaged rotation, mapped into the
// prior's frame by the median of R_prior_i R_bootstrap_i^T, and keeps its prior centre.
PoseSet RepairRotations(const PoseSet& prior, const PoseSet& bootstrap,
                        PriorRepairSummary* summary = nullptr);

// The repair decided from the data (paper §5: the configuration follows checks on the data, not
// an oracle of the prior's quality). The prior is coarse when its rotations are further than
// `min_rotation_change_deg` from the averaged ones (median over the registered images, the gauge
// rotation taken out); a coarse prior is replaced by the bootstrap (ReplaceWithBootstrap) when
// the bootstrap's positions are supported by the graph, and gets the averaged rotations only
// (RepairRotations) when they are not (a near-pure-rotation sweep: look-at centres). A prior
// that is not coarse is returned unchanged: its rotations may be better than the averaged ones.
// summary->mode says what was done: "none", "rotations" or "replace".
PoseSet RepairIfCoarse(const PoseSet& prior, const PoseSet& bootstrap,
                       double min_rotation_change_deg, bool bootstrap_positions_supported,
                       PriorRepairSummary* summary = nullptr);

// Full replacement: bootstrap poses mapped into the prior's frame by a similarity whose rotation
// is the median of R_prior_i R_bootstrap_i^T (as RepairRotations) and whose scale and translation
// fit the bootstrap centres onto the prior centres; the Umeyama fit of centres alone when that
// scale is not positive. Needs >= 3 registered images (std::invalid_argument otherwise).
PoseSet ReplaceWithBootstrap(const PoseSet& prior, const PoseSet& bootstrap,
                             PriorRepairSummary* summary = nullptr);

}  // namespace raytime
