#include "refine/solve/ray_time_lm_solver.h"

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "core/timing.h"
#include "refine/solve/arctan_loss.h"
#include "refine/solve/ray_time_lm_kernel.h"
#include "refine/solve/ray_time_lm_linearization.h"
#include "refine/solve/reduced_camera_system.h"
#include "refine/solve/similarity_retraction.h"

namespace raytime {
namespace {

// Ceres' trust-region defaults (ceres::Solver::Options), so that an iteration limit or tolerance
// set for ceres_gnc.h means the same here.
constexpr double kInitialRadius = 1e4;
constexpr double kMaxRadius = 1e16;
constexpr double kMinRadius = 1e-32;
constexpr double kMinRelativeDecrease = 1e-3;
constexpr double kGradientTolerance = 1e-10;
// Step doubling (DoubleStep) after an accepted step whose actual decrease beat the model's by this
// factor: 1 is a model that is exact along the step, 2 a cost that is linear along it.
constexpr double kStepDoublingMinRelativeDecrease = 1.5;
constexpr double kParameterTolerance = 1e-8;

using Clock = std::chrono::steady_clock;

// Ceres' trust-region radius μ (the damping is D/μ): grown after a step the model predicted well,
// shrunk ever faster after rejected ones.
struct TrustRegion {
  double radius = kInitialRadius;
  double decrease_factor = 2.0;

  void Accept(double relative_decrease) {
    const double q = 2.0 * relative_decrease - 1.0;
    radius = std::min(kMaxRadius, radius / std::max(1.0 / 3.0, 1.0 - q * q * q));
    decrease_factor = 2.0;
  }
  // False once the radius is below Ceres' minimum.
  bool Reject() {
    radius /= decrease_factor;
    decrease_factor *= 2.0;
    return !(radius < kMinRadius);
  }
};

// One stage's solve: its loss, its tolerances, where it stands, and its summary.
struct LmStage {
  ScaledArctanLoss loss{};
  double function_tolerance = 0.0;
  int max_step_doublings = 0;
  double cost = 0.0;
  TrustRegion region;
  GncStageSummary summary;

  void Stop(GncTermination termination, const char* message) {
    summary.termination = termination;
    summary.message = message;
  }
};

// The ray-time LM as the GNC driver's back-end (gnc.h): the loop over the problem
// (ray_time_lm_kernel.h, ray_time_lm_linearization.h) and the reduced camera system.
class RayTimeLmBackend : public GncBackend {
 public:
  RayTimeLmBackend(RayTimeLmProblem* problem, int num_threads)
      : problem_(problem), system_(*problem), num_threads_(num_threads) {
    point_.world_from_cam = problem->world_from_cam;
    for (Rigid3& pose : point_.world_from_cam) pose.rotation.normalize();
    point_.ray_times = problem->ray_times;
    point_.UpdateRotations();
  }

  GncStageSummary SolveStage(double scale_px2, double function_tolerance,
                             const GncSettings& settings, GncProgress* progress) override;
  const char* Name() const override { return "ray-time LM"; }
  // The solver reads only the problem's sizes after it starts: storing into it mid-schedule is
  // safe.
  void Publish() override {
    problem_->world_from_cam = point_.world_from_cam;
    problem_->ray_times = point_.ray_times;
  }

 private:
  enum class StepOutcome { kRejected, kAccepted, kConverged };
  double TimedCost(const RayTimeLmPoint& point, LmStage* stage) const;
  StepOutcome TryStep(LmStage* stage);
  bool ParameterToleranceReached() const;
  void DoubleStep(const Eigen::Matrix<double, 7, 1>& similarity, LmStage* stage);

  RayTimeLmProblem* problem_;
  ReducedCameraSystem system_;
  int num_threads_;
  RayTimeLmPoint point_;
  RayTimeLmPoint candidate_;
  RayTimeLmPoint trial_;
  ReducedStep step_;
};

GncStageSummary RayTimeLmBackend::SolveStage(double scale_px2, double function_tolerance,
                                             const GncSettings& settings, GncProgress* progress) {
  const auto start = Clock::now();
  LmStage stage;
  stage.loss = {scale_px2, problem_->match_loss_weight};
  stage.function_tolerance = function_tolerance;
  stage.max_step_doublings = settings.max_step_doublings;
  GncStageSummary& summary = stage.summary;
  summary.loss_scale_px2 = scale_px2;
  stage.cost = TimedCost(point_, &stage);
  summary.initial_cost = stage.cost;
  stage.Stop(GncTermination::kNoConvergence, "Maximum number of iterations reached.");
  while (summary.iterations < settings.max_iterations) {
    auto t0 = Clock::now();
    LinearizeRayTimeLm(*problem_, point_, stage.loss, stage.region.radius, num_threads_, &system_);
    ++summary.jacobian_evaluations;
    summary.jacobian_seconds += SecondsSince(t0);
    // Ceres' gradient test: the max norm of the full gradient (cameras, and ray times projected
    // onto their bound) at or below kGradientTolerance is a stationary point.
    if (system_.gradient_max_norm() <= kGradientTolerance) {
      stage.Stop(GncTermination::kConvergence, "Gradient tolerance reached.");
      break;
    }
    t0 = Clock::now();
    const bool solved = system_.Solve(stage.region.radius, num_threads_, &step_);
    summary.linear_solver_seconds += SecondsSince(t0);
    ++summary.iterations;
    StepOutcome outcome = StepOutcome::kRejected;
    if (solved && std::isfinite(step_.model_decrease) && step_.model_decrease > 0.0) {
      outcome = TryStep(&stage);
    }
    if (outcome == StepOutcome::kConverged) break;
    if (outcome == StepOutcome::kRejected && !stage.region.Reject()) {
      if (solved) {
        stage.Stop(GncTermination::kConvergence, "Minimum trust region radius reached.");
      } else {
        stage.Stop(GncTermination::kFailure, "The reduced camera system could not be factorized.");
      }
      break;
    }
    progress->Report(summary.iterations, stage.cost);
  }
  summary.final_cost = stage.cost;
  summary.seconds = SecondsSince(start);
  return summary;
}

double RayTimeLmBackend::TimedCost(const RayTimeLmPoint& point, LmStage* stage) const {
  const auto t0 = Clock::now();
  const double cost =
      RayTimeLmCost(*problem_, point, stage->loss.scale, num_threads_, system_.pattern());
  stage->summary.residual_seconds += SecondsSince(t0);
  return cost;
}

// The candidate x ⊕ δ (RetractPoint), judged by Ceres' tests: the parameter tolerance, the ratio
// of the actual to the predicted decrease, the function tolerance.
RayTimeLmBackend::StepOutcome RayTimeLmBackend::TryStep(LmStage* stage) {
  const std::vector<int>& variables = system_.pattern().variables();
  const Eigen::Matrix<double, 7, 1> similarity =
      SimilarityPart(point_.world_from_cam, variables, step_.cameras);
  RetractPoint(point_, variables, step_, similarity, 1.0, &candidate_);
  if (ParameterToleranceReached()) {
    stage->Stop(GncTermination::kConvergence, "Parameter tolerance reached.");
    return StepOutcome::kConverged;
  }
  const double candidate_cost = TimedCost(candidate_, stage);
  const double cost_change = stage->cost - candidate_cost;
  const double relative_decrease = cost_change / step_.model_decrease;
  const bool accepted = std::isfinite(candidate_cost) && relative_decrease > kMinRelativeDecrease;
  const bool converged = std::isfinite(candidate_cost) &&
                         std::abs(cost_change) <= stage->function_tolerance * stage->cost;
  if (accepted) {
    std::swap(point_, candidate_);
    stage->cost = candidate_cost;
    ++stage->summary.successful_steps;
  }
  if (converged) {
    stage->Stop(GncTermination::kConvergence, "Function tolerance reached.");
    return StepOutcome::kConverged;
  }
  if (!accepted) return StepOutcome::kRejected;
  // The step fell by much more than the model said: the arctan's IRLS weights overstate the
  // curvature along it (matches in the loss's bend being let go, the anneal's slow creep of many
  // steps in one direction, each falling by twice the prediction; docs/scaling.md).
  if (relative_decrease > kStepDoublingMinRelativeDecrease) DoubleStep(similarity, stage);
  stage->region.Accept(relative_decrease);
  return StepOutcome::kAccepted;
}

// The parameter tolerance looks at the poses only: the points of far matches run out along their
// rays (ray times far beyond the scene's depth), and with them in |x| the test stopped the anneal
// after a few of its steps (measured: docs/scaling.md, "Measurements behind the LM's choices"). A
// ray time's step follows from the cameras' (it is eliminated exactly), so still cameras mean a
// still solution.
bool RayTimeLmBackend::ParameterToleranceReached() const {
  double step_norm2 = 0.0;
  double x_norm2 = 0.0;
  for (size_t i = 0; i < point_.world_from_cam.size(); ++i) {
    const Rigid3& pose = point_.world_from_cam[i];
    x_norm2 += pose.rotation.coeffs().squaredNorm() + pose.translation.squaredNorm();
    const int c = system_.pattern().variable(static_cast<int>(i));
    if (c >= 0) step_norm2 += step_.cameras.segment<6>(6 * c).squaredNorm();
  }
  return std::sqrt(step_norm2) <= kParameterTolerance * (std::sqrt(x_norm2) + kParameterTolerance);
}

// After an accepted step (the point it left is candidate_, swapped out), the step doubled while
// the cost keeps falling: in one iteration where the slow creep took many. Each try costs one
// cost evaluation, a quarter of an iteration.
void RayTimeLmBackend::DoubleStep(const Eigen::Matrix<double, 7, 1>& similarity, LmStage* stage) {
  const RayTimeLmPoint& step_start = candidate_;
  const std::vector<int>& variables = system_.pattern().variables();
  double alpha = 1.0;
  for (int d = 0; d < stage->max_step_doublings; ++d) {
    alpha *= 2.0;
    RetractPoint(step_start, variables, step_, similarity, alpha, &trial_);
    const double trial_cost = TimedCost(trial_, stage);
    if (!(trial_cost < stage->cost)) break;
    std::swap(point_, trial_);
    stage->cost = trial_cost;
    ++stage->summary.step_doublings;
  }
}

}  // namespace

std::vector<GncStageSummary> SolveGncRayTimeLm(RayTimeLmProblem* problem,
                                               const GncSettings& settings) {
  RayTimeLmBackend backend(problem, settings.num_threads);
  std::vector<GncStageSummary> stages = SolveGnc(&backend, settings);
  backend.Publish();
  return stages;
}

}  // namespace raytime
