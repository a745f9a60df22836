// The basin-first recipe (`recipe: basin_first`; issues 12 and 30, beyond the paper's single pass,
// cf. its §4.8 and §4.11): a basin pass at the full GNC schedule without an orientation prior, the
// wrong-pair removal rounds (pairs the basin solution leaves unexplained are removed and the basin
// solved again from the prior), the orientation-prior probe, the finish on all matches and the
// finish anneal. And the loose-parts verdict on what the removal left
// (refine/checks/loose_parts.h).
#pragma once

#include <optional>
#include <vector>

#include "core/geometry.h"
#include "refine/recipes/refine_pass.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"

namespace raytime {

// Runs the recipe from *state (the nominal pass's settings, the prior as every pass's anchor),
// appending its passes and the removal and probe verdicts to *summary. When pairs are removed,
// *pruned holds the input without them, which the caller's posterior checks use.
void RunBasinFirst(const RefineInput& input, const RefineOptions& options,
                   const PassSettings& nominal, const std::vector<Rigid3>& prior, PassState* state,
                   RefineSummary* summary, std::optional<RefineInput>* pruned);

// refine/checks/loose_parts.h's verdict on the input's match graph at the returned solution
// (*state); `removal` the recipe's (empty when it did not run).
LoosePartsVerdict CheckLooseParts(const RefineInput& input, const PairRemovalSummary& removal,
                                  const PassState& state, const RefineOptions& options,
                                  double threshold_px);

}  // namespace raytime
