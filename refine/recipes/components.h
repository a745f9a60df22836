// The match graph's connected components (issues 46, 48: refine owns its work). Each component is
// solved on its own (a solve has one gauge: a global similarity the matches do not see, fixed by
// the prior), an image no pair with matches touches is not solved at all, and what each solve
// returns is put back in the whole input's indices for the frame verdicts.
#pragma once

#include <vector>

#include "refine/refine_types.h"

namespace raytime {

struct MatchComponents {
  // Image indices (ascending) of each component of two or more images joined by pairs with
  // matches, largest first (ties: the one holding the smaller index).
  std::vector<std::vector<int>> components;
  std::vector<int> unmatched;  // images in no pair with matches, ascending
};

MatchComponents SplitMatchComponents(const RefineInput& input);

// `input` restricted to `images` (in that order; image k of the result is images[k]): their
// priors, cameras (the whole list, indexed as in the input), keypoints, names and warm start, and
// the pairs between them.
RefineInput ComponentInput(const RefineInput& input, const std::vector<int>& images);

// Writes one component's output into the whole input's: poses and diagnostics of images[k] from
// the component's image k, the cameras when `cameras` (the solve whose intrinsics are returned),
// and, when `solution_returned` (no guardrail returned the prior), its ray times and pass poses.
void MergeComponentOutput(const std::vector<int>& images, const RefineOutput& part, bool cameras,
                          bool solution_returned, RefineOutput* whole);

// The component summary's image indices (pairs, cuts, named images, per-image values) in the
// whole input's: images[k] for k; per-image vectors grow to `num_images` entries.
void ToInputIndices(const std::vector<int>& images, int num_images, RefineSummary* summary);

}  // namespace raytime
