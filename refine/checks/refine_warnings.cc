#include "refine/checks/refine_warnings.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <map>

#include "refine/solve/camera_blocks.h"

namespace raytime {
namespace {

// The first few names, then how many more.
std::string NameList(const std::vector<std::string>& names) {
  constexpr size_t kNamed = 8;
  std::string out;
  for (size_t i = 0; i < std::min(kNamed, names.size()); ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > kNamed) out += fmt::format(" and {} more", names.size() - kNamed);
  return out;
}

// The images a set of pairs shares: those in two or more of them; both of a single pair's.
std::vector<int> SharedImages(const std::vector<PairResidual>& pairs) {
  std::map<int, int> count;
  for (const PairResidual& pair : pairs) {
    ++count[pair.image1];
    ++count[pair.image2];
  }
  std::vector<int> out;
  for (const auto& [image, n] : count) {
    if (n >= 2 || pairs.size() == 1) out.push_back(image);
  }
  return out;
}

// Per verdict reason not held: the warning's code and what it says of its frames.
struct ReasonWarning {
  const char* code;
  const char* says;
};

const std::map<std::string, ReasonWarning>& DoubtedWarnings() {
  static const std::map<std::string, ReasonWarning> warnings = {
      {"unmatched",
       {"unmatched_cameras",
        "have a prior pose but no verified pair with another image: they are not refined and not "
        "in the refined poses"}},
      {"not_solved",
       {"unrefined_components",
        "lie in components of the match graph a self-calibrating run does not solve (it refines "
        "the largest only): they are not refined"}},
      {"non_finite", {"non_finite_poses", "came out of the solve with non-finite poses"}},
      {"intrinsics",
       {"wrong_intrinsics",
        "fit their matches far better with another focal length or principal point: their "
        "intrinsics are likely wrong, and so are their poses"}},
      {"unexplained_pairs",
       {"unexplained_images",
        "are left with all or most of their pairs unexplained by the solution: their poses are "
        "likely wrong"}},
      {"moved_and_fits_worse",
       {"frame_doubts",
        "moved far more than the others and fit their matches worse: wrong intrinsics, or frames "
        "the solve could not place"}},
      {"fits_far_worse",
       {"frame_doubts",
        "fit their matches far worse than the other frames: their matches do not place them "
        "(another scene's image, wrong intrinsics)"}},
      {"names_swapped",
       {"swapped_frames",
        "are each placed where the prior has another of them: their images or names are likely "
        "swapped"}},
      {"loose_part",
       {"loose_parts",
        "are not held to the rest by the matches (a part hanging on one or two pairs, or on "
        "fewer pairs than the wrong-pair removal took), and no trusted prior places them"}},
      {"disconnected",
       {"disconnected_unplaced",
        "lie in smaller components of the match graph, and no trusted prior places them relative "
        "to the largest"}},
  };
  return warnings;
}

}  // namespace

void AddSolveWarnings(const RefineInput& input, const RefineSummary& summary,
                      const std::vector<int>& images, Warnings* warnings) {
  std::vector<std::string> names;
  for (const int image : images) names.push_back(input.Label(image));
  if (summary.guardrails.returned_prior) {
    // The trust region fires when the matches pull the solution far from the prior: most often a
    // prior several degrees off, which the basin configuration is for (§4.8).
    const bool trust_region = summary.guardrails.fired.front() == "trust_region";
    warnings->push_back(
        {"returned_prior",
         "guardrail " + summary.guardrails.fired.front() +
             " fired: the refined poses of these images are the prior's, unrefined" +
             (trust_region ? std::string("; for a prior more than ~2° off, refine with preset "
                                         "auto (basin solve first, no trust region)")
                           : std::string()),
         names,
         {},
         {{"fired", summary.guardrails.fired}}});
  }
  if (summary.cameras.cameras_differ) {
    warnings->push_back(
        {"cameras_shared",
         "intrinsics_sharing 'shared' refined one set of intrinsics for images whose given cameras "
         "differ from it by up to " +
             fmt::format("{:.3g}", summary.cameras.max_start_disagreement_px) +
             " px on the image; their per-image intrinsics were replaced",
         names,
         {},
         {{"num_cameras", summary.cameras.num_cameras},
          {"max_start_disagreement_px", summary.cameras.max_start_disagreement_px},
          {"tolerance_px", kSharedCameraTolerancePx}}});
  }
  const InconsistentPairsVerdict& pairs = summary.guardrails.inconsistent_pairs;
  if (pairs.fired) {
    Warning warning{"inconsistent_pairs",
                    std::to_string(pairs.num_inconsistent) + " of " +
                        std::to_string(pairs.num_pairs) +
                        " image pairs keep matches the solution does not explain (wrong pairs, "
                        "e.g. repeated structure, may have pulled it off)",
                    {},
                    {},
                    {{"fraction", pairs.fraction},
                     {"fraction_threshold", pairs.fraction_threshold},
                     {"pair_threshold_px", pairs.pair_threshold_px}}};
    for (const PairResidual& pair : pairs.pairs) {
      warning.pairs.emplace_back(input.Label(pair.image1), input.Label(pair.image2));
    }
    for (const int image : SharedImages(pairs.pairs)) {
      warning.images.push_back(input.Label(image));
    }
    if (!warning.images.empty()) {
      warning.message += "; the pairs share " + NameList(warning.images);
    }
    warnings->push_back(warning);
  }
}

void AddFrameWarnings(const RefineInput& input, const std::vector<FrameVerdict>& verdicts,
                      const std::vector<ComponentSummary>& components,
                      const std::vector<std::vector<int>>& component_images, Warnings* warnings) {
  if (components.size() > 1) {
    Warning warning{
        "disconnected_graph", "", {}, {}, {{"component_sizes", nlohmann::json::array()}}};
    int solved = 0;
    for (size_t c = 0; c < components.size(); ++c) {
      warning.details["component_sizes"].push_back(components[c].num_images);
      solved += components[c].solved;
      if (c == 0) continue;
      for (const int image : component_images[c]) warning.images.push_back(input.Label(image));
    }
    warning.details["refined_components"] = solved;
    std::string sizes;
    for (size_t c = 0; c < components.size(); ++c) {
      sizes += (c ? ", " : "") + std::to_string(components[c].num_images);
    }
    warning.message = fmt::format(
        "the match graph has {} connected components ({} images); {}", components.size(), sizes,
        solved == 1 ? "only the largest is refined (self-calibration needs one solve)"
                    : "each is refined in its own gauge: the smaller ones are placed relative to "
                      "the largest by the prior alone (their frames' verdicts say whether a "
                      "trusted prior does so)");
    warnings->push_back(warning);
  }
  // Frames the trusted prior places: exported, and named.
  std::map<std::string, Warning> by_reason;
  Warning by_prior{"held_by_prior", "", {}, {}, nlohmann::json::object()};
  for (size_t i = 0; i < verdicts.size(); ++i) {
    const FrameVerdict& verdict = verdicts[i];
    const std::string name = input.Label(static_cast<int>(i));
    if (verdict.verdict == kVerdictHeldByPrior) {
      by_prior.images.push_back(name);
      by_prior.details[name] = verdict.detail;
      continue;
    }
    if (verdict.verdict != kVerdictDoubted || verdict.reason == "returned_prior") continue;
    Warning& warning = by_reason[verdict.reason];
    warning.images.push_back(name);
    warning.details[name] = verdict.detail;
  }
  if (!by_prior.images.empty()) {
    by_prior.message = fmt::format(
        "{} frame(s) are not held to the rest by their matches, but agree with the trusted prior, "
        "which places them; exported: {}",
        by_prior.images.size(), NameList(by_prior.images));
    warnings->push_back(by_prior);
  }
  for (auto& [reason, warning] : by_reason) {
    const auto known = DoubtedWarnings().find(reason);
    warning.code = known != DoubtedWarnings().end() ? known->second.code : reason;
    const std::string says =
        known != DoubtedWarnings().end() ? known->second.says : "are doubted (" + reason + ")";
    warning.message =
        fmt::format("{} frame(s) {}: {}{}", warning.images.size(), says, NameList(warning.images),
                    reason == "unmatched" || reason == "not_solved"
                        ? std::string()
                        : std::string("; left out of the refined export"));
    warnings->push_back(warning);
  }
}

}  // namespace raytime
