#include "refine/checks/loose_parts.h"

#include <algorithm>
#include <set>
#include <utility>

#include "core/graph.h"

namespace raytime {
namespace {

// `side` as the smaller side of its cut (ties: the side without image 0), ascending.
std::vector<int> SmallerSide(int num_images, const std::vector<int>& side) {
  std::vector<bool> in(num_images, false);
  for (const int image : side) in[image] = true;
  const int size = static_cast<int>(side.size());
  const bool keep = 2 * size < num_images || (2 * size == num_images && !in[0]);
  if (keep) return side;
  std::vector<int> other;
  for (int image = 0; image < num_images; ++image) {
    if (!in[image]) other.push_back(image);
  }
  return other;
}

LooseCut CountAcross(int num_images, std::vector<int> side, const std::vector<GraphPair>& pairs) {
  std::vector<bool> in(num_images, false);
  for (const int image : side) in[image] = true;
  LooseCut cut;
  cut.images = std::move(side);
  for (const GraphPair& pair : pairs) {
    if (in[pair.image1] == in[pair.image2]) continue;
    ++cut.pairs_across;
    cut.matches_across += pair.num_matches;
    if (pair.removed) {
      ++cut.pairs_removed;
      cut.matches_removed += pair.num_matches;
    }
  }
  return cut;
}

}  // namespace

std::vector<LooseCut> FindLooseCuts(int num_images, const std::vector<GraphPair>& pairs) {
  std::vector<std::pair<int, int>> before;
  std::vector<std::pair<int, int>> after;
  for (const GraphPair& pair : pairs) {
    before.emplace_back(pair.image1, pair.image2);
    if (!pair.removed) after.emplace_back(pair.image1, pair.image2);
  }
  std::set<std::vector<int>> sides;
  const auto add_cuts_of = [&](const std::vector<std::pair<int, int>>& edges) {
    for (const MinimumCut& cut : MinimumCutTree(num_images, edges)) {
      sides.insert(SmallerSide(num_images, cut.side));
    }
  };
  add_cuts_of(before);
  // Without a removal (the usual solve) the graph after it is the same one: its tree once.
  if (after.size() < before.size()) add_cuts_of(after);
  std::vector<LooseCut> loose;
  for (const std::vector<int>& side : sides) {
    LooseCut cut = CountAcross(num_images, side, pairs);
    const int pairs_left = cut.pairs_across - cut.pairs_removed;
    const int matches_left = cut.matches_across - cut.matches_removed;
    const bool weak = pairs_left <= kMaxPairsHoldingALoosePart ||
                      (pairs_left == 2 && matches_left < kMinMatchesHoldingAPartByTwoPairs);
    const bool cut_by_removal = cut.pairs_removed >= kMinPairsRemovedAcrossLooseCut &&
                                cut.pairs_removed > pairs_left &&
                                cut.matches_removed > matches_left;
    if (weak || cut_by_removal) {
      loose.push_back(std::move(cut));
    }
  }
  std::stable_sort(loose.begin(), loose.end(), [](const LooseCut& a, const LooseCut& b) {
    return a.images.size() < b.images.size();
  });
  return loose;
}

}  // namespace raytime
