// The ray-time refiner (SPEC §3; paper §3): refines camera poses (and optionally the
// intrinsics) from a coarse pose prior and feature matches in one sparse solve without
// triangulation. Entry point: RefinePoses. The solver never sees ground truth.
//
//   RefineInput input;             // cameras, prior world_from_cam, keypoints, matches
//   RefineOutput output;
//   const RefineSummary summary = RefinePoses(input, RefineOptions(), &output);
//   if (summary.guardrails.returned_prior) ...  // a guardrail fired: output holds the prior
//   if (!summary.guardrails.fired.empty()) ...  // also flag-only ones ("inconsistent_pairs")
#pragma once

#include "refine/refine_options.h"
#include "refine/refine_types.h"

namespace raytime {

// Refines input.prior_world_from_cam. Throws InputError on inconsistent input (sizes, keypoint
// indices out of range, image indices out of range) or invalid options.
RefineSummary RefinePoses(const RefineInput& input, const RefineOptions& options,
                          RefineOutput* output);

}  // namespace raytime
