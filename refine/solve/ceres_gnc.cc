#include "refine/solve/ceres_gnc.h"

#include <ceres/iteration_callback.h>
#include <ceres/solver.h>

#include <algorithm>

#include "core/interrupt.h"

namespace raytime {
namespace {

// Hands Ceres' iterations to the driver's progress log.
class CeresProgressCallback : public ceres::IterationCallback {
 public:
  explicit CeresProgressCallback(GncProgress* progress) : progress_(progress) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    // A rejected step's summary carries the candidate's (higher) cost; the solve is at the last
    // accepted one.
    if (summary.iteration == 0 || summary.step_is_successful) accepted_cost_ = summary.cost;
    // Not thrown through Ceres: the solve is aborted and the driver stops after it (gnc.cc).
    if (StopWasRequested()) return ceres::SOLVER_ABORT;
    progress_->Report(summary.iteration, accepted_cost_);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  GncProgress* progress_;
  double accepted_cost_ = 0.0;
};

// Ceres' reason to stop, as the driver's (the same names: TerminationTypeToString's).
GncTermination CeresStageTermination(ceres::TerminationType type) {
  switch (type) {
    case ceres::CONVERGENCE:
      return GncTermination::kConvergence;
    case ceres::NO_CONVERGENCE:
      return GncTermination::kNoConvergence;
    case ceres::FAILURE:
      return GncTermination::kFailure;
    case ceres::USER_SUCCESS:
      return GncTermination::kUserSuccess;
    case ceres::USER_FAILURE:
      return GncTermination::kUserFailure;
  }
  return GncTermination::kFailure;
}

class CeresStageBackend : public GncBackend {
 public:
  explicit CeresStageBackend(RayTimeProblem* problem) : problem_(problem) {}

  GncStageSummary SolveStage(double scale_px2, double function_tolerance,
                             const GncSettings& settings, GncProgress* progress) override {
    ceres::Solver::Options options;
    // §3.4: the reduced camera system after eliminating the 1x1 ray-time blocks, factorized by
    // sparse Cholesky; no ordering is given, so Ceres' automatic ordering picks the elimination
    // group (an independent set: exactly the ray times, since no residual holds two of them).
    options.linear_solver_type = ceres::SPARSE_SCHUR;
    options.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
    // §3.7 "Line search": the ray-time and focal bounds would trigger a projected line search
    // costing one extra Jacobian evaluation per iteration; the update is projected onto the
    // bounds regardless, so it is disabled.
    options.max_num_line_search_step_size_iterations = 0;
    options.num_threads = settings.num_threads;
    options.max_num_iterations = settings.max_iterations;
    options.function_tolerance = function_tolerance;
    options.logging_type = ceres::SILENT;
    options.minimizer_progress_to_stdout = false;
    CeresProgressCallback callback(progress);
    options.callbacks = {&callback};

    problem_->SetLossScale(scale_px2);
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem_->problem(), &summary);
    GncStageSummary stage;
    stage.loss_scale_px2 = scale_px2;
    stage.successful_steps = summary.num_successful_steps;
    stage.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
    stage.initial_cost = summary.initial_cost;
    stage.final_cost = summary.final_cost;
    stage.seconds = summary.total_time_in_seconds;
    stage.jacobian_seconds = summary.jacobian_evaluation_time_in_seconds;
    stage.residual_seconds = summary.residual_evaluation_time_in_seconds;
    stage.linear_solver_seconds = summary.linear_solver_time_in_seconds;
    stage.jacobian_evaluations = summary.num_jacobian_evaluations;
    stage.termination = CeresStageTermination(summary.termination_type);
    stage.message = summary.message;
    if (elimination_group_size_ < 0) {
      elimination_group_size_ = summary.linear_solver_ordering_used.empty()
                                    ? 0
                                    : summary.linear_solver_ordering_used.front();
    }
    return stage;
  }

  const char* Name() const override { return "Ceres"; }
  // The first stage's; -1 before any.
  int elimination_group_size() const { return elimination_group_size_; }

 private:
  RayTimeProblem* problem_;
  int elimination_group_size_ = -1;
};

}  // namespace

std::vector<GncStageSummary> SolveGncWithCeres(RayTimeProblem* problem, const GncSettings& settings,
                                               int* elimination_group_size) {
  CeresStageBackend backend(problem);
  std::vector<GncStageSummary> stages = SolveGnc(&backend, settings);
  if (elimination_group_size != nullptr) {
    *elimination_group_size = std::max(0, backend.elimination_group_size());
  }
  return stages;
}

}  // namespace raytime
