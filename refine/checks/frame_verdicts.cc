#include "refine/checks/frame_verdicts.h"

#include <fmt/format.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <stdexcept>

#include "core/statistics.h"

namespace raytime {
namespace {

// Below this many reference frames the prior's accuracy is not measured (and a part is not placed
// by it): a similarity and a spread need a few frames.
constexpr int kMinReferenceFrames = 3;
// Measured tolerance: max(kMedianMultiple x the median, kQuantileMultiple x the 90th percentile)
// of the reference frames' disagreement with the prior; a stated accuracy σ gives kStatedSigmas σ.
constexpr double kMedianMultiple = 3.0;
constexpr double kQuantileMultiple = 1.5;
constexpr double kStatedSigmas = 3.0;
// Floors of the measured tolerance, so that a prior that agrees to the last digit (a synthetic or
// an already refined one) still leaves room for the solve's own noise: degrees, and a fraction of
// the prior's extent (median distance of its centres from their centroid).
constexpr double kMinRotationToleranceDeg = 0.05;
constexpr double kMinCentreToleranceFraction = 0.002;
// A prior the probe did not keep (one frame's glitch can raise the median residual under the
// orientation prior past its threshold: one of 60 corridor frames rotated 18° did) or did not
// probe (a preset without it) is still trusted when the frames the matches hold agree with it this
// closely (median, after the trimmed fit): a phone's tracking, 0.1-0.4° and 0.2-0.7 % of the
// capture's extent on the shared captures, not a coarse prior of a degree or more.
constexpr double kMaxMeasuredRotationDeg = 0.5;
constexpr double kMaxMeasuredCentreFraction = 0.01;

// A similarity mapping the solution's world onto the prior's: x_prior = s R x_solution + t.
struct SolutionToPrior {
  double scale = 1.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

// R the chordal mean of R_prior R_solutionᵀ over `frames` (well posed for centres on a line, a
// corridor walk), s and t by least squares on the centres with R fixed. False for no frame or
// solution centres that all coincide.
bool FitSolutionToPrior(const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
                        const std::vector<int>& frames, SolutionToPrior* fit) {
  if (frames.empty()) return false;
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d mean_solution = Eigen::Vector3d::Zero(), mean_prior = Eigen::Vector3d::Zero();
  for (const int i : frames) {
    sum +=
        prior[i].rotation.toRotationMatrix() * solution[i].rotation.toRotationMatrix().transpose();
    mean_solution += solution[i].translation / static_cast<double>(frames.size());
    mean_prior += prior[i].translation / static_cast<double>(frames.size());
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  fit->rotation = svd.matrixU() * d * svd.matrixV().transpose();
  double numerator = 0.0, denominator = 0.0;
  for (const int i : frames) {
    const Eigen::Vector3d a = fit->rotation * (solution[i].translation - mean_solution);
    numerator += a.dot(prior[i].translation - mean_prior);
    denominator += a.squaredNorm();
  }
  if (!(denominator > 0)) {
    if (frames.size() > 1) return false;
    fit->scale = 1.0;
  } else {
    fit->scale = numerator > 0 ? numerator / denominator : 1.0;
  }
  fit->translation = mean_prior - fit->scale * fit->rotation * mean_solution;
  return true;
}

struct Disagreement {
  double rotation_deg = 0.0;
  double centre = 0.0;  // prior length units
};

Disagreement DisagreementOf(const SolutionToPrior& fit, const Rigid3& prior,
                            const Rigid3& solution) {
  const Eigen::Matrix3d aligned = fit.rotation * solution.rotation.toRotationMatrix();
  Disagreement out;
  out.rotation_deg =
      DegreesFromRadians(RotationAngle(prior.rotation.toRotationMatrix().transpose() * aligned));
  out.centre =
      (fit.scale * fit.rotation * solution.translation + fit.translation - prior.translation)
          .norm();
  return out;
}

// Median distance of the prior's centres from their centroid.
double PriorExtent(const std::vector<Rigid3>& prior) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Rigid3& pose : prior) centroid += pose.translation / static_cast<double>(prior.size());
  std::vector<double> distances;
  for (const Rigid3& pose : prior) distances.push_back((pose.translation - centroid).norm());
  return Median(distances, 0.0);
}

// Whether the prior is trusted, measured on `reference`, with the fit of the solution onto it.
// The fit and the measures leave out the reference frames more than kOutlierMultiple times the
// median away (in rotation or centre) after a first fit: a tracking glitch the solve fixed, or a
// swapped frame, is no measure of the prior's accuracy. `disagreements` receives those left in.
constexpr double kOutlierMultiple = 3.0;

PriorTrust JudgePrior(const FrameEvidence& evidence, std::vector<int> reference,
                      SolutionToPrior* fit, bool* fitted,
                      std::vector<Disagreement>* disagreements) {
  PriorTrust trust;
  *fitted = static_cast<int>(reference.size()) >= kMinReferenceFrames &&
            FitSolutionToPrior(evidence.prior, evidence.solution, reference, fit);
  std::vector<double> rotations, centres;
  if (*fitted) {
    for (const int i : reference) {
      const Disagreement d = DisagreementOf(*fit, evidence.prior[i], evidence.solution[i]);
      rotations.push_back(d.rotation_deg);
      centres.push_back(d.centre);
    }
    const double max_rotation =
        std::max(kOutlierMultiple * Median(rotations, 0.0), kMinRotationToleranceDeg);
    const double max_centre = std::max(kOutlierMultiple * Median(centres, 0.0),
                                       kMinCentreToleranceFraction * PriorExtent(evidence.prior));
    std::vector<int> inliers;
    for (size_t k = 0; k < reference.size(); ++k) {
      if (rotations[k] <= max_rotation && centres[k] <= max_centre) inliers.push_back(reference[k]);
    }
    if (static_cast<int>(inliers.size()) >= kMinReferenceFrames &&
        inliers.size() < reference.size()) {
      SolutionToPrior refit;
      if (FitSolutionToPrior(evidence.prior, evidence.solution, inliers, &refit)) {
        *fit = refit;
        reference = inliers;
      }
    }
    rotations.clear();
    centres.clear();
    for (const int i : reference) {
      const Disagreement d = DisagreementOf(*fit, evidence.prior[i], evidence.solution[i]);
      disagreements->push_back(d);
      rotations.push_back(d.rotation_deg);
      centres.push_back(d.centre);
    }
    trust.median_rotation_deg = Median(rotations, 0.0);
    trust.median_centre = Median(centres, 0.0);
  }
  trust.num_reference_frames = static_cast<int>(reference.size());
  if (evidence.stated.Stated()) {
    trust.trusted = true;
    trust.source = "stated";
    const double inf = std::numeric_limits<double>::infinity();
    trust.rotation_tolerance_deg =
        evidence.stated.rotation_deg > 0 ? kStatedSigmas * evidence.stated.rotation_deg : inf;
    trust.centre_tolerance =
        evidence.stated.centre > 0 ? kStatedSigmas * evidence.stated.centre : inf;
    return trust;
  }
  const bool accurate =
      *fitted && trust.median_rotation_deg <= kMaxMeasuredRotationDeg &&
      trust.median_centre <= kMaxMeasuredCentreFraction * PriorExtent(evidence.prior);
  if (evidence.prior_from_matches) {
    trust.source = "prior_from_matches";
  } else if (evidence.probe_kept) {
    trust.trusted = true;
    trust.source = "probe";
  } else if (accurate) {
    trust.trusted = true;
    trust.source = "measured";
  } else {
    trust.source = evidence.probe_run ? "probe_dropped" : "not_probed";
  }
  if (*fitted) {
    trust.rotation_tolerance_deg = std::max(
        {kMedianMultiple * trust.median_rotation_deg,
         kQuantileMultiple * NearestRankQuantile(rotations, 0.9, 0.0), kMinRotationToleranceDeg});
    trust.centre_tolerance = std::max({kMedianMultiple * trust.median_centre,
                                       kQuantileMultiple * NearestRankQuantile(centres, 0.9, 0.0),
                                       kMinCentreToleranceFraction * PriorExtent(evidence.prior)});
  }
  return trust;
}

std::string Degrees(double value) { return fmt::format("{:.3g}°", value); }

// Two frames placed each where the other's prior is, and not where their own is: their images
// (or names) were swapped. Measured in units of the reference frames' 90th-percentile
// disagreement (at least the tolerance floors): each frame is within kSwapNormal units of the
// other's prior, like a reference frame, and not of its own (more than kSwapNormal, and kSwapRatio
// times the other's). Both frames must show it: one glitch does not sit on another frame's pose. A
// swap within the prior's own noise is no more visible than it is harmful; a frame whose solve only
// fixed its prior (a tracking glitch) matches no other frame's prior.
constexpr double kSwapNormal = 2.0;
constexpr double kSwapRatio = 2.0;

std::vector<FrameFinding> FindSwappedNames(const FrameEvidence& evidence,
                                           const std::vector<FrameVerdict>& verdicts,
                                           const SolutionToPrior& fit,
                                           const std::vector<Disagreement>& reference) {
  std::vector<double> rotations, centres;
  for (const Disagreement& d : reference) {
    rotations.push_back(d.rotation_deg);
    centres.push_back(d.centre);
  }
  const double unit_rotation =
      std::max(NearestRankQuantile(rotations, 0.9, 0.0), kMinRotationToleranceDeg);
  const double unit_centre = std::max(NearestRankQuantile(centres, 0.9, 0.0),
                                      kMinCentreToleranceFraction * PriorExtent(evidence.prior));
  const auto units = [&](int frame, int prior) {
    const Disagreement d = DisagreementOf(fit, evidence.prior[prior], evidence.solution[frame]);
    return std::max(d.rotation_deg / unit_rotation, d.centre / unit_centre);
  };
  // Frames a check already doubted count too (their findings stand; a swap only adds to them).
  std::vector<int> off;
  for (size_t i = 0; i < evidence.solution.size(); ++i) {
    if (evidence.component[i] < 0) continue;
    if (units(static_cast<int>(i), static_cast<int>(i)) > kSwapNormal) {
      off.push_back(static_cast<int>(i));
    }
  }
  std::vector<FrameFinding> findings;
  std::set<int> taken;
  for (size_t a = 0; a < off.size(); ++a) {
    for (size_t b = a + 1; b < off.size(); ++b) {
      const int i = off[a], j = off[b];
      if (taken.count(i) || taken.count(j)) continue;
      const double own_i = units(i, i), own_j = units(j, j);
      const double swapped_i = units(i, j), swapped_j = units(j, i);
      if (swapped_i > kSwapNormal || swapped_j > kSwapNormal || own_i < kSwapRatio * swapped_i ||
          own_j < kSwapRatio * swapped_j) {
        continue;
      }
      taken.insert(i);
      taken.insert(j);
      for (const auto& [frame, other] : {std::pair(i, j), std::pair(j, i)}) {
        const Disagreement own =
            DisagreementOf(fit, evidence.prior[frame], evidence.solution[frame]);
        const Disagreement there =
            DisagreementOf(fit, evidence.prior[other], evidence.solution[frame]);
        findings.push_back(
            {frame, "names_swapped",
             fmt::format("its matches place it where the prior has {} ({} / {:.3g} from it) and "
                         "{} where the prior has this frame, both far from their own prior ({} / "
                         "{:.3g} here; the frames the matches hold are within {} / {:.3g}): the "
                         "two frames' images or names are likely swapped",
                         evidence.labels[other], Degrees(there.rotation_deg), there.centre,
                         evidence.labels[other], Degrees(own.rotation_deg), own.centre,
                         Degrees(unit_rotation), unit_centre)});
      }
    }
  }
  // One half of a swap whose other half a check doubted: that frame's placement is no evidence
  // (a part the pair removal cut loose, placed anywhere), so this frame, held where the doubted
  // one's prior is and far from its own, is the half that shows it.
  for (const int i : off) {
    if (taken.count(i) || verdicts[i].verdict != kVerdictHeld) continue;
    int partner = -1;
    double nearest = kSwapNormal;
    for (const int j : off) {
      if (j == i || verdicts[j].verdict == kVerdictHeld) continue;
      const double swapped = units(i, j);
      if (swapped <= nearest && units(i, i) >= kSwapRatio * swapped) {
        partner = j;
        nearest = swapped;
      }
    }
    if (partner < 0) continue;
    taken.insert(i);
    const Disagreement own = DisagreementOf(fit, evidence.prior[i], evidence.solution[i]);
    const Disagreement there = DisagreementOf(fit, evidence.prior[partner], evidence.solution[i]);
    findings.push_back(
        {i, "names_swapped",
         fmt::format("its matches place it where the prior has {} ({} / {:.3g} from it), far from "
                     "its own prior ({} / {:.3g}; the frames the matches hold are within {} / "
                     "{:.3g}), and {} is doubted ({}): the two frames' images or names are likely "
                     "swapped",
                     evidence.labels[partner], Degrees(there.rotation_deg), there.centre,
                     Degrees(own.rotation_deg), own.centre, Degrees(unit_rotation), unit_centre,
                     evidence.labels[partner], verdicts[partner].reason)});
  }
  return findings;
}

// The images of each part the matches do not hold, with the sentence that says why: every loose
// cut's smaller side, and every component but the largest (no pair to it at all).
struct LoosePart {
  std::vector<int> images;
  std::string reason;  // loose_part or disconnected
  std::string why;
};

std::vector<LoosePart> LooseParts(const FrameEvidence& evidence) {
  std::vector<LoosePart> parts;
  for (const LooseCut& cut : evidence.loose_cuts) {
    const int pairs_left = cut.pairs_across - cut.pairs_removed;
    const int matches_left = cut.matches_across - cut.matches_removed;
    parts.push_back(
        {cut.images, "loose_part",
         fmt::format("its part of {} frame(s) hangs on the rest by {} pair(s) of {} matches{}, "
                     "which do not fix its placement",
                     cut.images.size(), pairs_left, matches_left,
                     cut.pairs_removed == 0
                         ? std::string()
                         : fmt::format(" (the wrong-pair removal took {} of the {} pairs across)",
                                       cut.pairs_removed, cut.pairs_across))});
  }
  std::map<int, std::vector<int>> components;
  for (size_t i = 0; i < evidence.component.size(); ++i) {
    if (evidence.component[i] > 0) components[evidence.component[i]].push_back(static_cast<int>(i));
  }
  for (const auto& [component, images] : components) {
    parts.push_back({images, "disconnected",
                     fmt::format("its component of {} frame(s) has no verified pair to the "
                                 "largest: only the prior places it relative to the rest",
                                 images.size())});
  }
  return parts;
}

// Per part, whether the trusted prior places it: the median over its frames of the disagreement
// within the tolerance. A misplaced part (turned about the pair it hangs on, or scaled along it)
// moves most of its frames off; one frame whose prior glitched, inside a part its matches hold
// together, does not.
bool PriorAgrees(const std::vector<Disagreement>& part, const PriorTrust& trust) {
  std::vector<double> rotations, centres;
  for (const Disagreement& d : part) {
    rotations.push_back(d.rotation_deg);
    centres.push_back(d.centre);
  }
  return Median(rotations, 0.0) <= trust.rotation_tolerance_deg &&
         Median(centres, 0.0) <= trust.centre_tolerance;
}

std::string WhyNotTrusted(const PriorTrust& trust) {
  if (trust.source == "probe_dropped") {
    return "the prior is not trusted to place it (the orientation probe found the matches "
           "contradict its rotations, and the frames they hold disagree with it by more than "
           "0.5° or 1 % of its extent)";
  }
  if (trust.source == "prior_from_matches") {
    return "the prior cannot place it (its rotations were estimated from these same matches)";
  }
  return "the prior is not trusted to place it (not probed, and the frames the matches hold "
         "disagree with it by more than 0.5° or 1 % of its extent; state its accuracy with "
         "prior.sigma_deg / prior.sigma_m to let it)";
}

}  // namespace

std::vector<FrameVerdict> JudgeFrames(const FrameEvidence& evidence, PriorTrust* trust) {
  const size_t n = evidence.prior.size();
  if (evidence.solution.size() != n || evidence.component.size() != n ||
      evidence.labels.size() != n) {
    throw std::invalid_argument("JudgeFrames: inconsistent sizes");
  }
  std::vector<FrameVerdict> verdicts(n);
  // 1. What the checks found, most decisive first.
  for (const FrameFinding& finding : evidence.findings) {
    FrameVerdict& verdict = verdicts.at(finding.image);
    if (verdict.verdict != kVerdictHeld) continue;
    verdict = {kVerdictDoubted, finding.reason, finding.detail};
  }
  // 2. The reference: frames of the largest component the matches hold and no check named.
  const std::vector<LoosePart> parts = LooseParts(evidence);
  std::vector<bool> in_part(n, false);
  for (const LoosePart& part : parts) {
    for (const int i : part.images) in_part[i] = true;
  }
  std::vector<int> reference;
  for (size_t i = 0; i < n; ++i) {
    if (verdicts[i].verdict == kVerdictHeld && evidence.component[i] == 0 && !in_part[i]) {
      reference.push_back(static_cast<int>(i));
    }
  }
  SolutionToPrior fit;
  bool fitted = false;
  std::vector<Disagreement> reference_disagreements;
  *trust = JudgePrior(evidence, reference, &fit, &fitted, &reference_disagreements);
  // 3. Swapped names, measured against the same fit (trusted prior or not: a swap moves two
  // frames far beyond how the others disagree with it).
  if (fitted) {
    for (const FrameFinding& finding :
         FindSwappedNames(evidence, verdicts, fit, reference_disagreements)) {
      verdicts[finding.image] = {kVerdictDoubted, finding.reason, finding.detail};
    }
  }
  // 4. The parts the matches do not hold: placed by a trusted prior that agrees, else doubted.
  std::vector<std::pair<std::string, std::string>> part_verdict(n);  // reason, detail
  std::vector<bool> agrees(n, true);
  for (const LoosePart& part : parts) {
    std::vector<Disagreement> disagreements;
    for (const int i : part.images) {
      if (verdicts[i].verdict != kVerdictHeld) continue;
      disagreements.push_back(DisagreementOf(fit, evidence.prior[i], evidence.solution[i]));
    }
    if (disagreements.empty()) continue;
    // A component of its own is solved in its own gauge, which the gauge polish fits to the
    // prior: the prior alone places it, and there is nothing across to compare. A loose part is
    // compared with the prior through the frames the matches hold.
    const bool placed = trust->trusted && (part.reason == "disconnected" ||
                                           (fitted && PriorAgrees(disagreements, *trust)));
    std::vector<double> rotations, centres;
    for (const Disagreement& d : disagreements) {
      rotations.push_back(d.rotation_deg);
      centres.push_back(d.centre);
    }
    const std::string numbers =
        part.reason == "disconnected" ? std::string("its placement is the prior's")
        : fitted
            ? fmt::format(
                  "{} / {:.3g} from the prior (median over the part; tolerance {} / "
                  "{:.3g})",
                  Degrees(Median(rotations, 0.0)), Median(centres, 0.0),
                  Degrees(trust->rotation_tolerance_deg), trust->centre_tolerance)
            : std::string("too few frames are held by the matches to compare it with the prior");
    const std::string detail =
        placed ? fmt::format("{}; the trusted prior ({}) places it, and agrees: {}", part.why,
                             trust->source, numbers)
        : trust->trusted
            ? fmt::format("{}; it disagrees with the trusted prior: {}", part.why, numbers)
            : fmt::format("{}; {}", part.why, WhyNotTrusted(*trust));
    for (const int i : part.images) {
      if (verdicts[i].verdict != kVerdictHeld) continue;
      // A frame in several parts (nested cuts) is placed only if every one of them agrees; the
      // first (smallest) part's sentence says why.
      if (part_verdict[i].first.empty() || (agrees[i] && !placed)) {
        part_verdict[i] = {part.reason, detail};
      }
      agrees[i] = agrees[i] && placed;
    }
  }
  for (size_t i = 0; i < n; ++i) {
    if (part_verdict[i].first.empty()) continue;
    verdicts[i] = {agrees[i] ? kVerdictHeldByPrior : kVerdictDoubted, part_verdict[i].first,
                   part_verdict[i].second};
  }
  return verdicts;
}

}  // namespace raytime
