#include "refine/gnc_solver.h"

#include <ceres/iteration_callback.h>
#include <ceres/solver.h>
#include <spdlog/spdlog.h>

#include <chrono>

namespace raytime {
namespace {

// A long solve (hundreds of cameras, millions of residuals: minutes per GNC stage) says it is
// alive: one log line per iteration, at most every `kProgressInterval`. It only reads the
// iteration summary, so results do not depend on it.
class ProgressLog : public ceres::IterationCallback {
 public:
  ProgressLog(int stage, int num_stages, double scale)
      : stage_(stage), num_stages_(num_stages), scale_(scale) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    // A rejected step's summary carries the candidate's (higher) cost; the solve is at the last
    // accepted one.
    if (summary.iteration == 0 || summary.step_is_successful) accepted_cost_ = summary.cost;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ >= kProgressInterval) {
      last_ = now;
      spdlog::info(
          fmt::format("refine: GNC stage {}/{} a = {:g} px²: iteration {}, cost {:.6g}, {:.0f} s",
                      stage_, num_stages_, scale_, summary.iteration, accepted_cost_,
                      summary.cumulative_time_in_seconds));
    }
    return ceres::SOLVER_CONTINUE;
  }

 private:
  static constexpr std::chrono::seconds kProgressInterval{15};
  int stage_, num_stages_;
  double scale_;
  double accepted_cost_ = 0.0;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

}  // namespace

std::vector<GncStageSummary> SolveGnc(RayTimeProblem* problem, const GncSolverSettings& settings,
                                      int* elimination_group_size) {
  ceres::Solver::Options options;
  // §3.4: the reduced camera system after eliminating the 1x1 ray-time blocks, factorized by
  // sparse Cholesky; no ordering is given, so Ceres' automatic ordering picks the elimination
  // group (an independent set: exactly the ray times, since no residual holds two of them).
  options.linear_solver_type = ceres::SPARSE_SCHUR;
  options.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  // §3.7 "Line search": the ray-time and focal bounds would trigger a projected line search
  // costing one extra Jacobian evaluation per iteration; the update is projected onto the bounds
  // regardless, so it is disabled.
  options.max_num_line_search_step_size_iterations = 0;
  options.num_threads = settings.num_threads;
  options.max_num_iterations = settings.max_iterations;
  options.function_tolerance = settings.function_tolerance;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;

  std::vector<GncStageSummary> stages;
  for (size_t s = 0; s < settings.scales.size(); ++s) {
    const double scale = settings.scales[s];
    problem->SetLossScale(scale);
    ProgressLog progress(static_cast<int>(s) + 1, static_cast<int>(settings.scales.size()), scale);
    options.callbacks = {&progress};
    ceres::Solver::Summary ceres_summary;
    ceres::Solve(options, &problem->problem(), &ceres_summary);

    GncStageSummary stage;
    stage.loss_scale_px2 = scale;
    stage.successful_steps = ceres_summary.num_successful_steps;
    stage.iterations = ceres_summary.num_successful_steps + ceres_summary.num_unsuccessful_steps;
    stage.initial_cost = ceres_summary.initial_cost;
    stage.final_cost = ceres_summary.final_cost;
    stage.seconds = ceres_summary.total_time_in_seconds;
    stage.jacobian_seconds = ceres_summary.jacobian_evaluation_time_in_seconds;
    stage.residual_seconds = ceres_summary.residual_evaluation_time_in_seconds;
    stage.linear_solver_seconds = ceres_summary.linear_solver_time_in_seconds;
    stage.jacobian_evaluations = ceres_summary.num_jacobian_evaluations;
    stage.termination = ceres::TerminationTypeToString(ceres_summary.termination_type);
    stage.message = ceres_summary.message;
    if (s == 0 && elimination_group_size != nullptr) {
      *elimination_group_size = ceres_summary.linear_solver_ordering_used.empty()
                                    ? 0
                                    : ceres_summary.linear_solver_ordering_used.front();
    }
    spdlog::info(
        fmt::format("refine: GNC stage {}/{} a = {:g} px²: {} iterations, cost {:.6g} -> {:.6g}, "
                    "{:.2f} s ({})",
                    s + 1, settings.scales.size(), scale, stage.iterations, stage.initial_cost,
                    stage.final_cost, stage.seconds, stage.termination));
    stages.push_back(stage);
    if (ceres_summary.termination_type == ceres::FAILURE) break;
  }
  return stages;
}

}  // namespace raytime
