// One connected match graph's solve (refine/recipes/components.h splits the input): the intrinsics
// blocks, a recipe of passes (refine_pass.h: one pass, the two of the staged room recipe of §4.3,
// or the basin-first recipe of basin_first.h), the pose uncertainty, the posterior guardrails
// (§3.6, §4.3, and the checks beyond the paper: inconsistent pairs, loose parts) and the frame
// checks whose findings the frame verdicts read (refine/checks/frame_verdicts.h).
#pragma once

#include <vector>

#include "refine/checks/frame_verdicts.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"

namespace raytime {

// Solves `input` (its match graph connected) into *output, its indices; *findings receives the
// frames the checks named, most decisive first.
RefineSummary SolveConnected(const RefineInput& input, const RefineOptions& options,
                             RefineOutput* output, std::vector<FrameFinding>* findings);

}  // namespace raytime
