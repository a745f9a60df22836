// Posterior guardrails (paper §3.6 "Prior trust region", §4.3 room-scale wander test): checks of
// a finished solve against the prior it started from, and one against its own matches (the
// inconsistent-pairs test, beyond the paper). Plain Eigen; RefinePoses decides what to return.
#pragma once

#include <vector>

#include "refine/refine_types.h"

namespace raytime {

// Per-frame rotation angle and centre displacement of `solution` from `prior`, maxima over
// frames, measured in the prior's own frame without alignment: the position prior anchors the
// solve's gauge (a global similarity) to the prior's metric frame (§3.3), so a correct solve
// has no gauge offset to remove, and a twist that aligned away would hide exactly the motion the
// envelope bounds (castle, §4.11). Fires when either maximum exceeds its threshold.
TrustRegionVerdict CheckTrustRegion(const std::vector<Rigid3>& prior,
                                    const std::vector<Rigid3>& solution,
                                    double rotation_threshold_deg, double translation_threshold);

// Per frame, the distance from the prior's centre to the solution's after a Sim(3) fit of the
// solution's centres onto the prior's (Umeyama): how far the solve moved each frame, a change of
// gauge taken out. False when fewer than three non-collinear centres determine no Sim(3): then
// the distances are measured without alignment.
bool CentreChangesAfterSim3(const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
                            std::vector<double>* changes);

// Median per-frame centre displacement of `solution` from `prior` after a Sim(3) fit of the
// solution's centres onto the prior's (Umeyama), so that a gauge drift of a room solve does not
// count as wander; fires above factor × expected. With fewer than three non-collinear centres no
// Sim(3) is determined and the displacement is measured without alignment.
WanderVerdict CheckWander(const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
                          double expected, double factor);

// Fewest inconsistent pairs that name their shared image when they are only most of its pairs
// (InconsistentPairsVerdict::images_mostly_inconsistent): two wrong pairs of one image are what
// repeated structure leaves. All of an image's pairs, however few, name it.
inline constexpr int kMinInconsistentPairsOfAnImage = 3;

// Inconsistent-pairs test (beyond the paper; cf. its §4.11 "Failure analysis"): a pair whose
// median positive-ray epipolar distance at the solve (PairResidualMedians, pair_consistency.h)
// exceeds max(`pair_threshold_px`, `median_multiple` x the median over the pairs of that measure)
// is inconsistent (the second term scales the threshold to a capture whose keypoints are noisier
// as a whole, e.g. a phone's rolling shutter, while a wrong pair stays off by many times the
// healthy pairs' noise); fires when the inconsistent fraction of `pairs`
// exceeds `max_fraction`. Prior-independent and blind to the ray times: correct solved poses
// explain every correct pair to the keypoint noise whatever prior the solve started from and
// wherever its ray times ended, while the matches of a wrong pair (repeated structure matched to
// the wrong copy) agree with another relative pose and stay off by the difference between the
// two. A handful of such pairs is the front end's usual residue; many of them pull the
// solution off (castle-P19). Quiet on no pairs. Also names the images most of whose pairs are
// inconsistent.
InconsistentPairsVerdict CheckInconsistentPairs(const std::vector<PairResidual>& pairs,
                                                double pair_threshold_px, double median_multiple,
                                                double max_fraction);

}  // namespace raytime
