// Graduated non-convexity (paper §3.5) and the Ceres mapping of §3.7: the arctan scale is
// annealed over a list of stages on one problem object, each Solve warm-started from the
// previous stage's parameters; matches, caches and sparsity are built once.
#pragma once

#include <vector>

#include "refine/ray_time_problem.h"

namespace raytime {

struct GncSolverSettings {
  std::vector<double> scales;  // arctan scales a, px², in solve order; the last is nominal
  int max_iterations = 100;    // per stage
  double function_tolerance = 1e-6;
  int num_threads = 1;  // Ceres' threads; 1 is deterministic (RefineOptions::deterministic)
};

// Solves every stage; stops early after a stage whose Ceres termination is FAILURE.
// `elimination_group_size` receives the size of the first elimination group Ceres' automatic
// ordering chose (the ray times, §3.4).
std::vector<GncStageSummary> SolveGnc(RayTimeProblem* problem, const GncSolverSettings& settings,
                                      int* elimination_group_size);

}  // namespace raytime
