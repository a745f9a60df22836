#include "refine/recipes/basin_first.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <utility>

#include "core/geometry.h"
#include "core/graph.h"
#include "refine/checks/loose_parts.h"

namespace raytime {
namespace {

// The match graph's edges: (image1, image2) of every pair with matches, in input order.
std::vector<std::pair<int, int>> MatchedEdges(const RefineInput& input) {
  std::vector<std::pair<int, int>> edges;
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.matches.rows() > 0) edges.emplace_back(pair.image1, pair.image2);
  }
  return edges;
}

int CountComponents(int num_images, const std::vector<std::pair<int, int>>& edges) {
  const std::vector<int> labels = ConnectedComponents(num_images, edges);
  return labels.empty() ? 0 : *std::max_element(labels.begin(), labels.end()) + 1;
}

// The pairs of `input` that `residuals` (of every pair, any order) put above threshold_px,
// worst first, except one whose removal would split the match graph further (appended to
// *kept): the pairs to leave out of the next solve.
std::vector<PairResidual> SelectInconsistentPairs(std::vector<PairResidual> residuals,
                                                  double threshold_px, const RefineInput& input,
                                                  std::vector<PairResidual>* kept) {
  std::stable_sort(
      residuals.begin(), residuals.end(),
      [](const PairResidual& a, const PairResidual& b) { return a.median_px > b.median_px; });
  const int num_images = static_cast<int>(input.prior_world_from_cam.size());
  std::vector<std::pair<int, int>> edges = MatchedEdges(input);
  const int components = CountComponents(num_images, edges);
  std::vector<PairResidual> selected;
  for (const PairResidual& residual : residuals) {
    if (!(residual.median_px > threshold_px)) break;  // sorted; infinite, never NaN
    const auto it =
        std::find(edges.begin(), edges.end(), std::make_pair(residual.image1, residual.image2));
    if (it == edges.end()) continue;
    const auto index = it - edges.begin();
    edges.erase(it);
    if (CountComponents(num_images, edges) > components) {
      edges.insert(edges.begin() + index, {residual.image1, residual.image2});
      kept->push_back(residual);
      continue;
    }
    selected.push_back(residual);
  }
  return selected;
}

// The (image1, image2) keys of `pairs`.
std::set<std::pair<int, int>> PairKeys(const std::vector<PairResidual>& pairs) {
  std::set<std::pair<int, int>> keys;
  for (const PairResidual& pair : pairs) keys.emplace(pair.image1, pair.image2);
  return keys;
}

// `input` without the pairs of `removed` (every other field as it is).
RefineInput WithoutPairs(const RefineInput& input, const std::vector<PairResidual>& removed) {
  const std::set<std::pair<int, int>> drop = PairKeys(removed);
  RefineInput out = input;
  out.pairs.erase(std::remove_if(out.pairs.begin(), out.pairs.end(),
                                 [&](const PairMatchIndices& pair) {
                                   return drop.count({pair.image1, pair.image2}) > 0;
                                 }),
                  out.pairs.end());
  return out;
}

bool SamePairs(const std::vector<PairResidual>& a, const std::vector<PairResidual>& b) {
  return PairKeys(a) == PairKeys(b);
}

// The finish anneal's arctan scale (RefineOptions::finish_noise_multiple): (k m)², m the basin's
// median residual, at least kMinFinishAnnealScalePx2; 0 when that is not below loss_scale_px2 (no
// anneal).
double FinishAnnealScale(const RefineOptions& options, double basin_median_px) {
  // SIFT keypoints are located to about half a pixel: a median below that says the basin fitted
  // few matches closely (or the data is noise-free), not that matches half a pixel off are wrong.
  // Without this floor, a noise-free synthetic scene's median of 1e-5 px gave a scale of 1e-10
  // px², where every residual is in the loss's flat tail and the solve drifted 0.8°.
  constexpr double kMinFinishAnnealScalePx2 = 0.25;
  const double target = std::max(std::pow(options.finish_noise_multiple * basin_median_px, 2),
                                 kMinFinishAnnealScalePx2);
  return options.finish_noise_multiple > 0 && target < options.loss_scale_px2 ? target : 0.0;
}

}  // namespace

// A pair the removal took counts as
// removed only while the returned solution leaves it unexplained (above threshold_px, on the
// basin's capped matches): a removal made at a pulled-off basin solution whose pairs the finish
// explains again took nothing that held a part (an oscillating removal took 13 of a correct desk
// frame's 18 pairs so).
LoosePartsVerdict CheckLooseParts(const RefineInput& input, const PairRemovalSummary& removal,
                                  const PassState& state, const RefineOptions& options,
                                  double threshold_px) {
  std::set<std::pair<int, int>> unexplained;
  if (!removal.removed.empty()) {
    const std::set<std::pair<int, int>> removed = PairKeys(removal.removed);
    RefineInput removed_only = input;
    removed_only.pairs.clear();
    for (const PairMatchIndices& pair : input.pairs) {
      if (removed.count({pair.image1, pair.image2})) removed_only.pairs.push_back(pair);
    }
    const ProblemLayout layout = BuildPerObservationLayout(
        removed_only, options.basin_max_matches_per_pair, options.match_cap_seed);
    for (const PairResidual& pair :
         PairResidualsAt(removed_only, layout, state.world_from_cam, state.cameras)) {
      if (!(pair.median_px <= threshold_px)) unexplained.emplace(pair.image1, pair.image2);
    }
  }
  std::vector<GraphPair> graph;
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.matches.rows() == 0) continue;
    graph.push_back({pair.image1, pair.image2, static_cast<int>(pair.matches.rows()),
                     unexplained.count({pair.image1, pair.image2}) > 0});
  }
  LoosePartsVerdict verdict;
  verdict.cuts = FindLooseCuts(static_cast<int>(input.prior_world_from_cam.size()), graph);
  std::set<int> images;
  for (const LooseCut& cut : verdict.cuts) images.insert(cut.images.begin(), cut.images.end());
  verdict.images.assign(images.begin(), images.end());
  return verdict;
}

namespace {

// Wrong-pair removal: every pair of the input is judged at the current basin solution (on the
// basin's capped matches), and the basin is solved again from the prior without the ones above
// the threshold, until the solution leaves exactly the pairs it was solved without (or none)
// above it. Judging the removed pairs again matters: a solution pulled off by wrong pairs leaves
// some correct ones off too, and they come back once it is right. Solving from the prior again
// (not from the pulled-off solution, `start`) gives the GNC schedule its whole basin. Returns the
// input the later passes use (*pruned when pairs were removed).
const RefineInput* RemoveWrongPairs(const RefineInput& input, const RefineOptions& options,
                                    const PassSettings& basin, const std::vector<Rigid3>& prior,
                                    const PassState& start, PassState* state,
                                    RefineSummary* summary, std::optional<RefineInput>* pruned,
                                    size_t* solution_pass) {
  const RefineInput* active = &input;
  *solution_pass = summary->passes.size() - 1;  // the basin's
  PairRemovalSummary& removal = summary->pair_removal;
  removal.enabled = options.max_pair_removal_rounds > 0;
  if (removal.enabled) {
    const ProblemLayout judged = BuildPerObservationLayout(
        input, options.basin_max_matches_per_pair, options.match_cap_seed);
    // Each round's solution by the pairs it was solved without: a round that would remove a set
    // an earlier round removed would solve the same problem from the same start (the solve is
    // deterministic) and reach that round's solution, so it is taken instead (the removals cycle).
    std::map<std::set<std::pair<int, int>>, std::pair<PassState, size_t>> solved_without = {
        {{}, {*state, *solution_pass}}};
    while (true) {
      const std::vector<PairResidual> residuals =
          PairResidualsAt(input, judged, state->world_from_cam, state->cameras);
      std::vector<PairResidual> kept;
      const std::vector<PairResidual> selected =
          SelectInconsistentPairs(residuals, options.inconsistent_pair_px, input, &kept);
      if (selected.empty() && kept.empty() && removal.removed.empty()) {
        removal.stop_reason = "consistent";
        break;
      }
      if (SamePairs(selected, removal.removed)) {
        // Nothing removable but bridges above the threshold: they are still reported.
        if (removal.rounds == 0) removal.kept = kept;
        removal.stop_reason = selected.empty() && removal.kept.empty() ? "consistent" : "stable";
        break;
      }
      if (removal.rounds == options.max_pair_removal_rounds) {
        removal.stop_reason = "max_rounds";
        break;
      }
      ++removal.rounds;
      removal.removed = selected;
      removal.kept = kept;
      pruned->emplace(WithoutPairs(input, selected));
      active = &pruned->value();
      const auto solved = solved_without.find(PairKeys(selected));
      if (solved != solved_without.end()) {
        spdlog::info(fmt::format(
            "refine: the {} pairs above {:.3g} px at the basin solution are the ones an earlier "
            "round removed: the removals cycle; that round's solution stands (round {} of at most "
            "{})",
            selected.size(), options.inconsistent_pair_px, removal.rounds,
            options.max_pair_removal_rounds));
        *state = solved->second.first;
        *solution_pass = solved->second.second;
        removal.stop_reason = "cycle";
        break;
      }
      spdlog::info(fmt::format(
          "refine: {} of {} pairs above {:.3g} px at the basin solution{}{}; solving the basin "
          "again from the prior without them (round {} of at most {})",
          selected.size(), residuals.size(), options.inconsistent_pair_px,
          selected.empty() ? std::string()
                           : fmt::format(" (worst ({}, {}) {:.1f} px)", selected.front().image1,
                                         selected.front().image2, selected.front().median_px),
          kept.empty() ? std::string()
                       : fmt::format(", {} kept to hold the graph together", kept.size()),
          removal.rounds, options.max_pair_removal_rounds));
      *state = start;
      PassSettings again = basin;
      again.name = "basin_round" + std::to_string(removal.rounds + 1);
      summary->passes.push_back(RunPass(*active, options, again, prior, state));
      *solution_pass = summary->passes.size() - 1;
      solved_without[PairKeys(selected)] = {*state, *solution_pass};
    }
  }
  return active;
}

// The orientation-prior probe: a pass with the nominal λR from the basin solution; the finish
// keeps λR only when the matches' median residual rises by at most orientation_prior_max_increase
// under it, and otherwise starts from the basin solution again. Not run for a prior estimated from
// these matches.
void ProbeOrientationPrior(const RefineInput& active, const RefineOptions& options,
                           const PassSettings& nominal, const PassSettings& basin,
                           const std::vector<Rigid3>& prior, size_t basin_pass, PassState* state,
                           RefineSummary* summary) {
  const PassState basin_state = *state;
  const RefinePassSummary basin_solution = summary->passes.at(basin_pass);

  OrientationPriorProbe& probe = summary->orientation_prior;
  probe.enabled = true;
  probe.weight = nominal.orientation_weight;
  probe.max_increase = options.orientation_prior_max_increase;
  probe.free_residual_median_px = basin_solution.residual_median_px;
  probe.free_match_cost_px2 = basin_solution.match_cost_px2;
  probe.prior_from_matches = active.prior_rotations_from_matches && probe.weight > 0;
  if (probe.prior_from_matches) {
    spdlog::info(fmt::format(
        "refine: orientation prior (λR = {:g}) not used: the prior's rotations were estimated "
        "from these matches (the bootstrap or a repair from it), so they add nothing but their "
        "own errors; the finish runs with λR = 0",
        probe.weight));
  } else if (probe.weight > 0) {
    PassSettings probe_pass = basin;
    probe_pass.name = "orientation_probe";
    probe_pass.orientation_weight = probe.weight;
    probe_pass.scales = {nominal.scales.back()};
    summary->passes.push_back(RunPass(active, options, probe_pass, prior, state));
    probe.prior_residual_median_px = summary->passes.back().residual_median_px;
    probe.prior_match_cost_px2 = summary->passes.back().match_cost_px2;
    probe.increase = probe.free_residual_median_px > 0
                         ? probe.prior_residual_median_px / probe.free_residual_median_px - 1.0
                         : 0.0;
    for (size_t i = 0; i < prior.size(); ++i) {
      probe.max_rotation_change_deg = std::max(
          probe.max_rotation_change_deg, RotationDistance(basin_state.world_from_cam[i].rotation,
                                                          state->world_from_cam[i].rotation) *
                                             180.0 / M_PI);
    }
    probe.kept = probe.increase <= probe.max_increase;
    if (probe.kept) {
      spdlog::info(fmt::format(
          "refine: orientation prior (λR = {:g}) kept: the matches agree with the prior's "
          "rotations (median residual {:+.2f} % under it, threshold {:+.2f} %; rotations moved "
          "up to {:.3f}°)",
          probe.weight, 100 * probe.increase, 100 * probe.max_increase,
          probe.max_rotation_change_deg));
    } else {
      spdlog::info(fmt::format(
          "refine: orientation prior (λR = {:g}) dropped: the matches contradict the prior's "
          "rotations (median residual {:+.2f} % under it, threshold {:+.2f} %; it moved rotations "
          "up to {:.3f}°); the finish runs with λR = 0 from the basin solve",
          probe.weight, 100 * probe.increase, 100 * probe.max_increase,
          probe.max_rotation_change_deg));
      *state = basin_state;
    }
  }
}

}  // namespace

void RunBasinFirst(const RefineInput& input, const RefineOptions& options,
                   const PassSettings& nominal, const std::vector<Rigid3>& prior, PassState* state,
                   RefineSummary* summary, std::optional<RefineInput>* pruned) {
  PassSettings basin;
  basin.name = "basin";
  basin.max_matches_per_pair = options.basin_max_matches_per_pair;
  basin.orientation_weight = 0.0;
  basin.scales = nominal.scales;
  basin.intermediate = true;  // and so its removal rounds and the probe, copied from it
  const PassState start = *state;
  summary->passes.push_back(RunPass(input, options, basin, prior, state));

  size_t basin_pass = 0;  // the pass whose solution the removal returns
  const RefineInput* active =
      RemoveWrongPairs(input, options, basin, prior, start, state, summary, pruned, &basin_pass);
  ProbeOrientationPrior(*active, options, nominal, basin, prior, basin_pass, state, summary);
  const OrientationPriorProbe& probe = summary->orientation_prior;

  PassSettings finish = nominal;
  finish.name = "finish";
  finish.scales = {nominal.scales.back()};
  finish.orientation_weight = probe.kept ? nominal.orientation_weight : 0.0;
  finish.start_unsolved_at_closest_approach = true;
  const double anneal_scale = FinishAnnealScale(options, probe.free_residual_median_px);
  finish.intermediate = anneal_scale > 0;
  summary->passes.push_back(RunPass(*active, options, finish, prior, state));
  // The finish anneal (RefineOptions::finish_noise_multiple) keeps the finish's orientation prior
  // but not its anchor: after a λR = 0 finish none; after a finish that kept λR, the same λR
  // towards the finish's own rotations. Towards the prior's (λR as it is), a prior the probe kept
  // but that is slightly wrong (a 1° ladder prior: +4.8 % median residual, just under the
  // threshold) took the rotations back as the shrinking scale weakened the matches' pull: 1.0-2.2°
  // on 4 of 24 ladder runs at 1-2°, one of them unflagged. With no prior at all, the long Record3D
  // desk sweep drifted 0.196° (median relative rotation) from the finish, unflagged: the mode of
  // docs/real_captures.md that made the probe keep λR there; held at the finish it moved 0.012°.
  // At the finish's full λR the hold costs castle-P19 from an exact prior (0.122° against 0.039°
  // without it); RefineOptions::finish_anneal_hold_ratio weakens it (0.01 in auto). One stage,
  // straight to its scale: through the decade between, as GNC would, the same errors to 0.001° on
  // the four Strecha scenes at 0° and 8°, with 35 % more iterations.
  if (anneal_scale > 0) {
    PassSettings anneal = finish;
    anneal.name = "finish_anneal";
    anneal.scales = {anneal_scale};
    anneal.intermediate = false;  // its solution is the answer
    anneal.orientation_weight = finish.orientation_weight * options.finish_anneal_hold_ratio;
    // Never from an earlier run's anneal: at its small scale which matches sit in the arctan's
    // flat tail depends on where the pass starts, so the path matters. The chair grown from 18 to
    // 24 frames, the anneal started from the 18 frames' anneal: 0.016° from a fresh run (cost
    // +0.4 %); started from this run's finish, as a fresh run does: 0.0002°.
    anneal.warm_startable = false;
    // Only the rotations: the centres' terms and the gauge stay the prior's, as in every pass.
    std::vector<Rigid3> anchor = prior;
    for (size_t i = 0; i < anchor.size(); ++i) {
      anchor[i].rotation = state->world_from_cam[i].rotation;
    }
    spdlog::info(fmt::format(
        "refine: the finish anneals on to {:.3g} px² ({:g} x the basin's median residual {:.3f} "
        "px, squared), {}",
        anneal_scale, options.finish_noise_multiple, probe.free_residual_median_px,
        anneal.orientation_weight > 0
            ? fmt::format("λR = {:g} towards the finish's rotations", anneal.orientation_weight)
            : std::string("λR = 0")));
    summary->passes.push_back(RunPass(*active, options, anneal, anchor, state));
  }
}

}  // namespace raytime
