// Initial ray times (paper §3.2; SPEC §3 "Ray point").
//
// The paper starts every ray time at 1 m, sane for metric object and room captures. On deeper
// scenes (the Strecha scenes are 8–25 m deep) that start is far from every point, and the first
// iterations drag the poses along while the ray times travel out. "auto" starts each image's ray
// times at a robust depth scale of that image instead: the median, over the residuals whose
// source ray lies in the image, of the depth along that ray of its closest approach to the target
// observation's ray under the prior poses, counting only pairs of rays that meet in front of
// both cameras. This is a scale per image, not structure: no point is triangulated or kept, no
// match is gated or culled, and every ray time of the image starts at the same value. An image
// without a sample takes the median over all samples; no sample at all falls back to the
// constant.
#pragma once

#include <string>
#include <vector>

#include "refine/refine_options.h"
#include "refine/solve/camera_blocks.h"
#include "refine/solve/problem_layout.h"

namespace raytime {

// Initial value of every ray time of `layout` (RefineOptions::ray_time_init). Each observation's
// ray is unprojected with its image's intrinsics in `cameras`.
std::vector<double> InitialRayTimes(const ProblemLayout& layout, const RefineInput& input,
                                    const std::vector<Rigid3>& world_from_cam,
                                    const CameraBlocks& cameras, RayTimeInitMode mode,
                                    double constant, RayTimeInitSummary* summary);

// The prior's depth scale: the median over the images of their "auto" start (above) at
// `world_from_cam`, on at most `max_matches_per_pair` matches per pair; NaN without a sample (no
// pair of rays meets in front of both cameras: a prior whose centres coincide).
double PriorDepthScale(const RefineInput& input, const std::vector<Rigid3>& world_from_cam,
                       const CameraBlocks& cameras, int max_matches_per_pair, int seed);

// The finish of the basin-first solve (`recipe: basin_first`) starts from poses an earlier
// pass solved on capped matches, and adds the observations the cap left out. Started at their
// image's depth scale, many of them would begin hundreds of pixels off, where the nominal arctan
// loss has no gradient, and stay there. Each ray time t with needs_start[t] starts instead at the
// median over its residuals of the depth, along its own ray, of the closest approach to the
// target observation's ray at `world_from_cam` (the solved poses, not the prior), over the pairs
// of rays that meet in front of both cameras; a ray time without such a residual keeps its value.
// A start per observation on its own ray, as the method's variables are: no point is built or
// shared between observations. Returns how many ray times were started so.
int StartRayTimesAtClosestApproach(const ProblemLayout& layout, const RefineInput& input,
                                   const std::vector<Rigid3>& world_from_cam,
                                   const CameraBlocks& cameras,
                                   const std::vector<bool>& needs_start,
                                   std::vector<double>* ray_times);

}  // namespace raytime
