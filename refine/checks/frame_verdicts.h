// A verdict for every frame of a run (issue 46; beyond the paper, cf. its §4.11 "Failure
// analysis"), made in one place from all the evidence the run has:
// - its matches: whether they fix the frame to the rest of the match graph
//   (refine/checks/loose_parts.h: every weakest cut, before and after the wrong-pair removal; a
//   component of its own has none);
// - its own residuals against the solve's: the checks of each solve name frames whose pairs the
//   solution leaves unexplained, that moved far more than the others and fit worse, whose matches
//   another focal length or principal point explains far better (refine/checks/frame_intrinsics.h);
// - the prior, where it is trusted: stated by the user (accuracies per frame), a capture's prior
//   whose rotations the orientation probe kept, or one the frames the matches do hold agree with
//   closely; its accuracy measured on those frames. A frame the matches do not hold is kept when
//   its placement relative to the rest agrees with a trusted prior within that accuracy; and two
//   frames each placed where the other's prior is, far from their own, are swapped names.
// Each frame is `held` (its matches fix it), `held_by_prior` (its matches do not, the trusted prior
// places it, and they agree) or `doubted` (with the reason). A loose part hanging on two pairs is
// as often right as wrong; what the checks built on the graph alone could not tell apart, the
// phone's prior can: a corridor walk's last third, held by 2 pairs of 57 matches, agreed with the
// phone's poses as well as the rest did and was right; the desk's six monitor frames, held by two
// pairs, were ~20° off the phone's.
#pragma once

#include <array>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "refine/checks/loose_parts.h"

namespace raytime {

inline constexpr const char* kVerdictHeld = "held";
inline constexpr const char* kVerdictHeldByPrior = "held_by_prior";
inline constexpr const char* kVerdictDoubted = "doubted";

struct FrameVerdict {
  std::string verdict = kVerdictHeld;
  // Why, where not held (stable codes, README "Frame verdicts"): loose_part, disconnected
  // (held_by_prior or doubted); unmatched, not_solved, returned_prior, non_finite (not refined);
  // unexplained_pairs, moved_and_fits_worse, fits_far_worse, intrinsics, names_swapped (doubted).
  std::string reason;
  std::string detail;  // one sentence with the numbers
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FrameVerdict, verdict, reason, detail)

// A frame one check named, and why (a reason code of FrameVerdict and a sentence).
struct FrameFinding {
  int image = 0;
  std::string reason;
  std::string detail;
};

// Accuracies the user states for the prior (prior stage: prior.sigma_deg, prior.sigma_m), per
// frame: rotation, degrees, and centre, prior length units. NaN: not stated.
struct StatedPriorAccuracy {
  double rotation_deg = std::numeric_limits<double>::quiet_NaN();
  double centre = std::numeric_limits<double>::quiet_NaN();
  bool Stated() const { return rotation_deg > 0 || centre > 0; }
};

// Whether the prior was trusted to place the frames the matches do not hold, and how closely the
// frames the matches do hold agree with it (after one similarity of the solution onto the prior
// fitted on them).
struct PriorTrust {
  bool trusted = false;
  // "stated" (the user's accuracies), "probe" (the orientation probe kept the prior's rotations),
  // "measured" (the frames the matches hold agree with it to 0.5° and 1 % of its extent), or why
  // not: "probe_dropped", "prior_from_matches", "not_probed".
  std::string source;
  int num_reference_frames = 0;  // held frames of the largest component the fit used
  double median_rotation_deg = std::numeric_limits<double>::quiet_NaN();
  double median_centre = std::numeric_limits<double>::quiet_NaN();  // prior length units
  // Agreement within the prior's accuracy: a part's median disagreement at most these (3 σ
  // stated; else max(3 x median, 1.5 x 90th percentile) over the reference frames).
  double rotation_tolerance_deg = std::numeric_limits<double>::quiet_NaN();
  double centre_tolerance = std::numeric_limits<double>::quiet_NaN();
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PriorTrust, trusted, source, num_reference_frames,
                                   median_rotation_deg, median_centre, rotation_tolerance_deg,
                                   centre_tolerance)

// What every frame's verdict is made from; vectors per image of the run.
struct FrameEvidence {
  std::vector<Rigid3> prior;
  std::vector<Rigid3> solution;  // the prior for a frame not refined
  // Per image: its component of the match graph (0 = the largest, solved first), -1 for none.
  std::vector<int> component;
  std::vector<LooseCut> loose_cuts;  // of every component's solve
  // From the checks, most decisive first: a frame's first finding is its reason.
  std::vector<FrameFinding> findings;
  StatedPriorAccuracy stated;
  bool probe_kept = false;          // the largest component's orientation probe kept the prior
  bool probe_run = false;           // ... ran at all
  bool prior_from_matches = false;  // the prior's rotations came from these matches
  std::vector<std::string> labels;  // per image, for the details
};

// One frame's intrinsics test (refine/checks/frame_intrinsics.h): its matches' median epipolar
// distance with its intrinsics as given and with the focal length and principal point free.
struct FrameIntrinsicsTest {
  int image = 0;
  int num_matches = 0;  // sampled matches to frames with a pose
  // Median over its pairs of each pair's median epipolar distance with its intrinsics as given:
  // at the solve; for a frame that fits worse than the others (`fitted`), after refitting its
  // pose, over the `pairs_judged` that fit or a free fit explains; and, fitted, the best with the
  // focal length, the principal point or both free (else the same as given).
  double given_median_px = 0.0;
  double free_median_px = 0.0;
  bool fitted = false;
  int pairs_judged = 0;
  double focal_factor = 1.0;                              // fitted focal / given
  std::array<double, 2> principal_shift_px = {0.0, 0.0};  // fitted - given, pixels
  bool named = false;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FrameIntrinsicsTest, image, num_matches, given_median_px,
                                   free_median_px, fitted, pairs_judged, focal_factor,
                                   principal_shift_px, named)

// The verdicts, per image; *trust says how the prior was judged.
std::vector<FrameVerdict> JudgeFrames(const FrameEvidence& evidence, PriorTrust* trust);

}  // namespace raytime
