// Graduated non-convexity (paper §3.5), one driver for both solvers (issue 31): the arctan scale
// is annealed over a list of stages on one problem, each stage warm-started from the previous
// stage's parameters; matches, caches and sparsity are built once. A back-end solves one stage:
// the ray-time Levenberg–Marquardt (ray_time_lm_solver.h) or Ceres (ceres_gnc.h).
#pragma once

#include <chrono>
#include <functional>
#include <vector>

#include "core/progress.h"
#include "refine/refine_types.h"

namespace raytime {

struct GncSettings {
  std::vector<double> scales;  // arctan scales a, px², in solve order; the last is nominal
  int max_iterations = 100;    // per stage, accepted and rejected steps
  // Relative cost-change tolerance of the stage whose solution is the solve's ...
  double function_tolerance = 1e-6;
  // ... and of a stage whose solution only starts another one: the schedule's earlier scales, and
  // every stage when `ends_solve` is false (the caller solves again from this solution). Their
  // minimum is not the answer, so a looser tolerance costs the last stage nothing measurable
  // (RefineOptions::intermediate_function_tolerance).
  double intermediate_function_tolerance = 1e-6;
  bool ends_solve = true;
  // Ray-time LM only: after an accepted step whose actual decrease beat the model's by half, up
  // to this many doublings of it while the cost keeps falling (RefineOptions::max_step_doublings).
  int max_step_doublings = 3;
  // The back-end's threads: the ray-time LM gives the same bits on any count; Ceres is
  // deterministic on 1 (RefineOptions::deterministic).
  int num_threads = 1;
  // The residual norms (pixels) at the back-end's current parameters, read after each stage for
  // its residual_histogram; empty: no histogram.
  std::function<std::vector<double>()> residual_norms;

  // The tolerance of stage `stage` (0-based) of `scales`.
  double StageTolerance(int stage) const;
};

// A long solve (hundreds of cameras, millions of residuals: minutes per stage) says it is alive:
// on a terminal a progress line (stage, iteration, cost; core/progress.h), else at most one log
// line every 15 s. It only reads the solve, so results do not depend on it.
class GncProgress {
 public:
  GncProgress(int stage, int num_stages, double scale_px2);
  // The stage's iteration count and the cost at its last accepted step.
  void Report(int iteration, double cost);

 private:
  int stage_;
  int num_stages_;
  double scale_px2_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_ = start_;
  ProgressBar bar_;
};

class GncBackend {
 public:
  virtual ~GncBackend() = default;
  // Solves one stage at arctan scale `scale_px2` from the current parameters, stopping at relative
  // cost change `function_tolerance`, and leaves them at its solution; termination kFailure ends
  // the schedule.
  virtual GncStageSummary SolveStage(double scale_px2, double function_tolerance,
                                     const GncSettings& settings, GncProgress* progress) = 0;
  // For the stage's log line ("ray-time LM", "Ceres").
  virtual const char* Name() const = 0;
  // Writes the current parameters into the problem the back-end solves, where the caller (and
  // GncSettings::residual_norms) reads them; a back-end that solves in place has nothing to do.
  virtual void Publish() {}
};

// Solves every stage of settings.scales in order with one log line per stage; stops after a stage
// that fails.
std::vector<GncStageSummary> SolveGnc(GncBackend* backend, const GncSettings& settings);

}  // namespace raytime
