#include "refine/checks/guardrails.h"

#include <algorithm>
#include <map>
#include <stdexcept>

#include "core/statistics.h"

namespace raytime {

TrustRegionVerdict CheckTrustRegion(const std::vector<Rigid3>& prior,
                                    const std::vector<Rigid3>& solution,
                                    double rotation_threshold_deg, double translation_threshold) {
  TrustRegionVerdict verdict;
  verdict.enabled = true;
  verdict.rotation_threshold_deg = rotation_threshold_deg;
  verdict.translation_threshold = translation_threshold;
  for (size_t i = 0; i < prior.size(); ++i) {
    verdict.max_rotation_deg =
        std::max(verdict.max_rotation_deg,
                 DegreesFromRadians(RotationDistance(prior[i].rotation, solution[i].rotation)));
    verdict.max_translation =
        std::max(verdict.max_translation, (prior[i].translation - solution[i].translation).norm());
  }
  verdict.fired = verdict.max_rotation_deg > rotation_threshold_deg ||
                  verdict.max_translation > translation_threshold;
  return verdict;
}

bool CentreChangesAfterSim3(const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
                            std::vector<double>* changes) {
  std::vector<Eigen::Vector3d> prior_centres, solution_centres;
  for (size_t i = 0; i < prior.size(); ++i) {
    prior_centres.push_back(prior[i].translation);
    solution_centres.push_back(solution[i].translation);
  }
  Sim3 prior_from_solution;
  bool aligned = true;
  try {
    prior_from_solution = FitAlignment(solution_centres, prior_centres, AlignmentKind::kSim3);
  } catch (const std::invalid_argument&) {
    aligned = false;
  }
  changes->clear();
  for (size_t i = 0; i < prior.size(); ++i) {
    changes->push_back((prior_from_solution * solution_centres[i] - prior_centres[i]).norm());
  }
  return aligned;
}

WanderVerdict CheckWander(const std::vector<Rigid3>& prior, const std::vector<Rigid3>& solution,
                          double expected, double factor) {
  WanderVerdict verdict;
  verdict.enabled = true;
  verdict.expected = expected;
  verdict.threshold = factor * expected;
  if (prior.empty()) return verdict;
  std::vector<double> displacements;
  CentreChangesAfterSim3(prior, solution, &displacements);
  verdict.median_displacement = UpperMedian(displacements, 0.0);
  verdict.fired = verdict.median_displacement > verdict.threshold;
  return verdict;
}

InconsistentPairsVerdict CheckInconsistentPairs(const std::vector<PairResidual>& pairs,
                                                double pair_threshold_px, double median_multiple,
                                                double max_fraction) {
  InconsistentPairsVerdict verdict;
  verdict.enabled = true;
  verdict.pair_threshold_px = pair_threshold_px;
  verdict.median_multiple = median_multiple;
  verdict.fraction_threshold = max_fraction;
  verdict.num_pairs = static_cast<int>(pairs.size());
  if (pairs.empty()) return verdict;
  std::vector<double> medians;
  for (const PairResidual& pair : pairs) medians.push_back(pair.median_px);
  verdict.median_pair_px = UpperMedian(medians, 0.0);
  verdict.pair_threshold_px = std::max(pair_threshold_px, median_multiple * verdict.median_pair_px);
  std::map<int, std::pair<int, int>> pairs_of_image;  // image -> (pairs, inconsistent pairs)
  for (const PairResidual& pair : pairs) {
    const bool inconsistent = pair.median_px > verdict.pair_threshold_px;
    if (inconsistent) verdict.pairs.push_back(pair);
    for (const int image : {pair.image1, pair.image2}) {
      ++pairs_of_image[image].first;
      if (inconsistent) ++pairs_of_image[image].second;
    }
  }
  verdict.num_inconsistent = static_cast<int>(verdict.pairs.size());
  for (const auto& [image, counts] : pairs_of_image) {
    // Most of three or more, or every one of its pairs (a frame with one or two pairs, both
    // unexplained, is a frame the solve did not place).
    const bool all = counts.second > 0 && counts.second == counts.first;
    if (all ||
        (counts.second >= kMinInconsistentPairsOfAnImage && 2 * counts.second > counts.first)) {
      verdict.images_mostly_inconsistent.push_back(image);
    }
  }
  verdict.fraction = static_cast<double>(verdict.num_inconsistent) / verdict.num_pairs;
  verdict.fired = verdict.fraction > max_fraction;
  return verdict;
}

}  // namespace raytime
