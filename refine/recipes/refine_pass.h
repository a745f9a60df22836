// One pass of the refiner (issue 31: refine/ by job): layout → ray-time initialization →
// problem → GNC on the ray-time LM or Ceres (RefineOptions::solver) → gauge polish, with the
// state a later pass starts from and what the checks read of the last one. The recipes (one pass,
// the staged room recipe, basin-first: RefineOptions::recipe) chain passes: connected_solve.cc,
// basin_first.h.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/geometry.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"
#include "refine/solve/camera_blocks.h"
#include "refine/solve/problem_layout.h"

namespace raytime {

// What differs between the passes of one run: the one source of a pass's cap, λR, GNC schedule and
// self-calibration. RunPass reads them here only (RefineOptions holds the nominal values, which
// NominalPass copies, and the run-wide ones: solver, tolerances, weights of the position prior).
struct PassSettings {
  std::string name;
  int max_matches_per_pair = 0;
  double orientation_weight = 0.0;
  std::vector<double> scales;
  bool refine_focal = false;
  bool refine_principal_point = false;
  bool refine_distortion = false;
  bool start_unsolved_at_closest_approach = false;  // StartRayTimesAtClosestApproach
  // Starts from the input's RefineWarmStart for this pass's name, where it has one (the passes on
  // all matches after the recipe's decisions).
  bool warm_startable = false;
  // The recipe solves again from this pass's solution (the basin, its rounds, the probe, a finish
  // the anneal follows, staged pass 1): every stage stops at the intermediate tolerance
  // (RefineOptions::intermediate_function_tolerance).
  bool intermediate = false;
};

// State carried from one pass to the next (the staged recipe's warm start), and the last pass's
// layout (its used matches) for the inconsistent-pairs test.
struct PassState {
  std::vector<Rigid3> world_from_cam;
  std::vector<Rigid3> anchor;  // the last pass's prior terms' anchor (its gauge polish's too)
  CameraBlocks cameras;        // the intrinsics blocks, at their current values
  std::unordered_map<uint64_t, double> ray_time_by_observation;  // keyed by (image, keypoint)
  // Per image, the median residual norm landing in it at the pass's solution (SolveDiagnostics).
  std::vector<double> image_residual_median_px;
  ProblemLayout layout;
  std::map<std::string, std::vector<Rigid3>> pass_world_from_cam;  // RefineOutput's
};

// The nominal pass: the options' cap, λR, GNC schedule and self-calibration, warm-startable (the
// passes on all matches after the recipe's decisions may start from an earlier run's solution).
PassSettings NominalPass(const RefineOptions& options);

// Solves one pass from *state (poses, intrinsics blocks, solved ray times) with the poses' prior
// terms towards `anchor`, and leaves its solution and layout in *state.
RefinePassSummary RunPass(const RefineInput& input, const RefineOptions& options,
                          const PassSettings& settings, const std::vector<Rigid3>& anchor,
                          PassState* state);

// How well the last pass's solution (in *state) determines each camera (pose_uncertainty.h), with
// that pass's summary `last`; not computed after a self-calibrating pass or when turned off.
PoseUncertaintySummary PoseUncertaintyOf(const RefineInput& input, const RefineOptions& options,
                                         const PassState& state, const RefinePassSummary& last,
                                         const std::vector<Rigid3>& prior);

// The last pass's observations, their solved ray times and its used matches (RefineOutput).
SolvedObservations SolvedObservationsOf(const PassState& state);

// Per image pair with matches in `layout`, its median positive-ray epipolar distance at the given
// poses and intrinsics blocks (PairResidualMedians' plain arrays from the layout; input order).
std::vector<PairResidual> PairResidualsAt(const RefineInput& input, const ProblemLayout& layout,
                                          const std::vector<Rigid3>& world_from_cam,
                                          const CameraBlocks& cameras);

// The same at the last pass's solved poses and intrinsics, on its used matches.
std::vector<PairResidual> SolvedPairResiduals(const RefineInput& input, const PassState& state);

// The blocks of the last pass's layout and the fewest observations one of them has.
void CountBlocks(const PassState& state, CameraBlocksSummary* summary);

}  // namespace raytime
