// The Ceres back-end of the GNC driver (gnc.h) and the Ceres mapping of §3.7: each stage one
// ceres::Solve of the ray-time problem (ray_time_problem.h) at its arctan scale, SPARSE_SCHUR with
// the ray times eliminated. Used for self-calibration, `solver: ceres`, and as the autodiff
// reference the ray-time LM is tested against.
#pragma once

#include <vector>

#include "refine/solve/gnc.h"
#include "refine/solve/ray_time_problem.h"

namespace raytime {

// Solves every stage (SolveGnc); `elimination_group_size` receives the size of the first
// elimination group Ceres' automatic ordering chose (the ray times, §3.4).
std::vector<GncStageSummary> SolveGncWithCeres(RayTimeProblem* problem, const GncSettings& settings,
                                               int* elimination_group_size);

}  // namespace raytime
