// Benchmark of the ray-time refiner on a synthetic scene of realistic size (not a test; timings
// on a shared machine are noisy, so every comparison is a ratio of two runs made here, in this
// process, one after the other).
//
//   refine_bench [--cameras N] [--points P] [--gap G] [--threads T] [--level DEG]
//
// Prints: the ray-time LM solver vs Ceres on the fixed-intrinsics residual vs Ceres with
// automatic differentiation (shared evaluation cache off; Jacobian evaluation time per evaluation
// and whole solve, paper §3.7), GNC vs plain (paper §4.4: about 2x), cap 100 vs all matches (§4.7),
// and solve time against the number of matches (how the cost grows), and the drift of the "auto"
// and "constant" ray-time initializations from an exact prior.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench/bench_main.h"
#include "evaluate/perturbation.h"
#include "evaluate/pose_errors.h"
#include "refine/refine.h"
#include "testing/synthetic_scene.h"

namespace raytime {
namespace {

struct BenchOptions {
  int cameras = 24;
  int points = 3000;
  int gap = 3;
  int threads = 0;
  double level_deg = 4.0;
};

struct Run {
  RefineSummary summary;
  double rotation_error_deg = 0.0;  // mean, after Sim(3)
};

Run Solve(const SyntheticScene& scene, const RefineInput& input, RefineOptions options,
          int threads) {
  options.num_threads = threads;
  RefineOutput output;
  Run run;
  run.summary = RefinePoses(input, options, &output);
  PoseErrorOptions error_options;
  run.rotation_error_deg = ComputePoseErrors(ToPoseSet(output.world_from_cam),
                                             ToPoseSet(scene.ground_truth), error_options)
                               .mean_rotation_deg;
  return run;
}

double PerJacobianEvaluation(const RefineSummary& summary) {
  int evaluations = 0;
  for (const auto& pass : summary.passes) {
    for (const auto& stage : pass.stages) evaluations += stage.jacobian_evaluations;
  }
  return summary.timings.jacobian_seconds / std::max(1, evaluations);
}

void PrintRun(const char* label, const Run& run) {
  const RefinePassSummary& pass = run.summary.passes.back();
  std::printf(
      "  %-28s matches %7d  residuals %7d  ray times %7d  iterations %3d  solve %7.2f s"
      "  jacobian %6.2f s (%.4f s/eval)  rot err %.4f deg\n",
      label, pass.num_matches_used, pass.num_residuals, pass.num_ray_times,
      run.summary.total_iterations, run.summary.timings.solve_seconds,
      run.summary.timings.jacobian_seconds, PerJacobianEvaluation(run.summary),
      run.rotation_error_deg);
}

int Main(int argc, char** argv) {
  BenchOptions bench;
  for (int a = 1; a + 1 < argc; a += 2) {
    const std::string key = argv[a];
    const double value = std::atof(argv[a + 1]);
    if (key == "--cameras")
      bench.cameras = static_cast<int>(value);
    else if (key == "--points")
      bench.points = static_cast<int>(value);
    else if (key == "--gap")
      bench.gap = static_cast<int>(value);
    else if (key == "--threads")
      bench.threads = static_cast<int>(value);
    else if (key == "--level")
      bench.level_deg = value;
    else {
      std::fprintf(stderr, "unknown option %s\n", key.c_str());
      return 2;
    }
  }
  SyntheticSceneOptions scene_options;
  scene_options.num_cameras = bench.cameras;
  scene_options.num_points = bench.points;
  scene_options.max_pair_gap = bench.gap;
  scene_options.pixel_noise = 0.5;
  scene_options.outlier_fraction = 0.05;
  scene_options.distortion = true;
  const SyntheticScene scene = MakeSyntheticScene(scene_options);
  RefineInput input = scene.input;
  PerturbationOptions perturbation;
  perturbation.level_deg = bench.level_deg;
  perturbation.seed = 1;
  const PoseSet prior = PerturbPoses(ToPoseSet(scene.ground_truth), perturbation);
  input.prior_world_from_cam = FromPoseSet(prior, bench.cameras);
  RefineOptions base;  // the ladders' basin configuration: no trust region, λR = 0
  base.trust_region = false;
  base.orientation_weight = 0.0;
  const int threads = bench.threads > 0 ? bench.threads : base.Threads();
  std::printf(
      "refine_bench: %d cameras, %d points, pairs with gap <= %d, distorted, 0.5 px "
      "noise, 5%% outliers, prior %.0f deg i.i.d., %d threads\n",
      bench.cameras, bench.points, bench.gap, bench.level_deg, threads);

  std::printf("\n[1] solvers (GNC, all matches)\n");
  RefineOptions options = base;
  const Run cache_on = Solve(scene, input, options, threads);
  PrintRun("ray-time LM (default)", cache_on);
  options.solver = RefineSolver::kCeres;
  const Run ceres_fixed = Solve(scene, input, options, threads);
  PrintRun("Ceres, fixed residual", ceres_fixed);
  options.use_evaluation_cache = false;
  const Run cache_off = Solve(scene, input, options, threads);
  PrintRun("Ceres, autodiff (cache off)", cache_off);
  std::printf("  ratio Ceres / ray-time LM: whole solve %.2fx, per iteration %.2fx\n",
              ceres_fixed.summary.timings.solve_seconds / cache_on.summary.timings.solve_seconds,
              (ceres_fixed.summary.timings.solve_seconds / ceres_fixed.summary.total_iterations) /
                  (cache_on.summary.timings.solve_seconds / cache_on.summary.total_iterations));
  std::printf(
      "  ratio autodiff / fixed residual (Ceres): Jacobian evaluation %.2fx per evaluation "
      "(%.2fx total), whole solve %.2fx\n",
      PerJacobianEvaluation(cache_off.summary) / PerJacobianEvaluation(ceres_fixed.summary),
      cache_off.summary.timings.jacobian_seconds / ceres_fixed.summary.timings.jacobian_seconds,
      cache_off.summary.timings.solve_seconds / ceres_fixed.summary.timings.solve_seconds);

  std::printf("\n[2] GNC vs plain (all matches)\n");
  options = base;
  options.gnc_scales = {};
  const Run plain = Solve(scene, input, options, threads);
  PrintRun("plain (a = 100)", plain);
  PrintRun("GNC 1e4 -> 1e3 -> 1e2", cache_on);
  std::printf(
      "  ratio GNC/plain: solve %.2fx, iterations %.2fx (paper: about 2x)\n",
      cache_on.summary.timings.solve_seconds / plain.summary.timings.solve_seconds,
      static_cast<double>(cache_on.summary.total_iterations) / plain.summary.total_iterations);

  std::printf("\n[3] cap 100 vs all matches (GNC)\n");
  options = base;
  options.max_matches_per_pair = 100;
  const Run cap100 = Solve(scene, input, options, threads);
  PrintRun("cap 100", cap100);
  PrintRun("all", cache_on);
  std::printf("  ratio all/cap100: solve %.2fx, matches %.2fx\n",
              cache_on.summary.timings.solve_seconds / cap100.summary.timings.solve_seconds,
              static_cast<double>(cache_on.summary.passes[0].num_matches_used) /
                  cap100.summary.passes[0].num_matches_used);

  std::printf("\n[4] solve time against the number of matches (GNC, cap K per pair)\n");
  std::vector<std::pair<int, Run>> sizes;
  for (int cap : {25, 50, 100, 200, 400, 0}) {
    options = base;
    options.max_matches_per_pair = cap;
    const Run run = cap == 100 ? cap100
                    : cap == 0 ? cache_on
                               : Solve(scene, input, options, threads);
    const std::string label = cap == 0 ? std::string("all") : "cap " + std::to_string(cap);
    PrintRun(label.c_str(), run);
    sizes.emplace_back(cap, run);
  }
  const Run& smallest = sizes.front().second;
  std::printf("  %-10s %10s %12s %14s %16s\n", "K", "matches", "solve (s)", "x smallest",
              "s per 1k matches");
  for (const auto& [cap, run] : sizes) {
    const int matches = run.summary.passes[0].num_matches_used;
    std::printf("  %-10s %10d %12.2f %14.2f %16.4f\n",
                cap == 0 ? "all" : std::to_string(cap).c_str(), matches,
                run.summary.timings.solve_seconds,
                run.summary.timings.solve_seconds / smallest.summary.timings.solve_seconds,
                1000.0 * run.summary.timings.solve_seconds / matches);
  }

  std::printf(
      "\n[5] ray-time initialization from an exact prior (drift = mean rotation / centre "
      "error in the prior's frame; the prior is the ground truth)\n");
  RefineInput exact = scene.input;
  for (const char* preset : {"gnc", "basin"}) {
    for (const RayTimeInitMode init : {RayTimeInitMode::kAuto, RayTimeInitMode::kConstant}) {
      options = RefineOptions();
      options.trust_region = false;
      if (std::string(preset) == "basin") {
        options.orientation_weight = 0.0;
        options.max_matches_per_pair = 100;
      }
      options.ray_time_init = init;
      options.num_threads = threads;
      RefineOutput output;
      const RefineSummary summary = RefinePoses(exact, options, &output);
      PoseErrorOptions none;
      none.alignment = "none";
      const PoseErrorSummary drift =
          ComputePoseErrors(ToPoseSet(output.world_from_cam), ToPoseSet(scene.ground_truth), none);
      std::printf(
          "  %-6s %-9s init depth %6.2f m  drift %.4f deg / %.4f m  iterations %3d  "
          "solve %.2f s\n",
          preset, NameOf(init), summary.passes[0].ray_time_init.median_depth,
          drift.mean_rotation_deg, drift.mean_centre_m, summary.total_iterations,
          summary.timings.solve_seconds);
    }
  }
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  return raytime::BenchMain("refine_bench", raytime::Main, argc, argv);
}
