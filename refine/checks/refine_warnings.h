// What a run returns with a doubt, as warnings by image name (core/warnings.h; README "Warnings"):
// the guardrails a solve fired, and every frame not simply held, grouped by its verdict's reason
// (refine/checks/frame_verdicts.h). The poses are still written (reports score them), never as if
// the solve had succeeded quietly.
#pragma once

#include <string>
#include <vector>

#include "core/warnings.h"
#include "refine/refine_types.h"

namespace raytime {

// One component's solve (its summary in the input's indices, `images` its images): a guardrail
// that returned the prior, intrinsics shared by images whose cameras differ, pairs the solution
// leaves unexplained (listing the images those pairs share).
void AddSolveWarnings(const RefineInput& input, const RefineSummary& summary,
                      const std::vector<int>& images, Warnings* warnings);

// The graph in pieces (the smaller components' images), and per reason the frames not held.
void AddFrameWarnings(const RefineInput& input, const std::vector<FrameVerdict>& verdicts,
                      const std::vector<ComponentSummary>& components,
                      const std::vector<std::vector<int>>& component_images, Warnings* warnings);

}  // namespace raytime
