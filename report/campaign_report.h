// Campaign reports: a sweep's rows (one per run, WORKDIR/sweep.json) aggregated into cells per
// scene, perturbation level and arm, written as Markdown tables shaped like the paper's Table 5
// (basin of convergence), Table 6 (controls) and Table 8 (prior's own frame), and as a CSV of
// cells for plotting (SPEC §6; paper §4.8 "Basin of convergence", §4.9 "Refinement in the prior's
// own frame").
//
// An arm is a scored pose set: `prior` (the perturbed input, the baseline), `refined@gnc`,
// `classical`, `classical@mapper`, ... Rows are report/sweep_row.h's SweepRow: per arm and
// alignment its errors, per stage its time, which stage wrote each arm, and the swept values.
#pragma once

#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "report/sweep_row.h"

namespace raytime {

struct CampaignReportOptions {
  // A run succeeds for an arm when its mean rotation error after Sim(3) alignment is below this,
  // degrees (paper §4.8: 1°, four times nominal accuracy, no larger than the smallest level).
  double success_rotation_deg = 1.0;
  // Swept column naming the scene (its last path component is shown); when absent, all runs are
  // one scene.
  std::string scene_key = "dataset.root";
  // Swept column holding the perturbation level, degrees; when absent, all runs are one level.
  std::string level_key = "prior.level_deg";
  // The arm the "halves the prior's rotation error" count compares against, run by run.
  std::string baseline_arm = "prior";
};

// Wilson score interval of a binomial proportion (paper §4.8: intervals are Wilson 95 % scores);
// z = 1.959964 is the two-sided 95 % normal quantile. No trials gives [0, 1].
struct ProportionInterval {
  double lower = 0.0;
  double upper = 1.0;
};
ProportionInterval WilsonInterval(int successes, int trials, double z = 1.959964);

constexpr double kNoValue = std::numeric_limits<double>::quiet_NaN();

// The runs of one cell under one alignment ("sim3" or "none"). Medians are over runs of each
// run's mean error; NaN when no run contributes.
struct AlignedCellStats {
  int runs = 0;       // runs that scored the arm under this alignment
  int successes = 0;  // mean rotation error < success_rotation_deg
  double median_rotation_deg = kNoValue;
  double median_centre_m = kNoValue;
  // Mean centre error over the scene scale (PoseErrorSummary::mean_centre_relative), median over
  // the runs that report one.
  double median_centre_relative = kNoValue;
  // Alignment-free: each run's mean relative rotation error (PoseErrorSummary), median over runs.
  double median_relative_rotation_deg = kNoValue;
  // The alignment's own rotation, RMS (PoseErrorSummary::alignment_rotation_sigma_deg), median
  // over runs: Sim(3) rotation errors closer than this are not told apart by the fit.
  double median_alignment_rotation_sigma_deg = kNoValue;
  // Runs where the baseline arm was scored too, and those where this arm's mean rotation error is
  // at most half the baseline's (SPEC §6); both 0 for the baseline itself.
  int halving_runs = 0;
  int halves_baseline = 0;
};

// Scene-level reading of the success counts (paper §4.8: failures cluster by scene, so a scene
// counts only when every one of its runs at the level succeeds).
struct SceneSuccessCount {
  int scenes = 0;  // scenes with at least one run scoring the arm
  int scenes_all_succeed = 0;
};

struct CampaignCell {
  std::string scene;  // display name; kAllScenes for the pooled cells
  double level_deg = 0.0;
  std::string arm;
  AlignedCellStats sim3;  // the standard protocol: Umeyama on centres, with scale
  AlignedCellStats none;  // absolute frame: the prior's own metric frame (§4.9)
  // The stage that wrote the arm (`refined@X` <- `refine@X`) and its median time over the
  // cell's runs, seconds; "" and NaN when the sweep has no seconds.<stage> column for it.
  std::string stage_id;
  double median_seconds = kNoValue;
  // Pooled cells only: the scene-level reading under Sim(3).
  SceneSuccessCount scene_success;
};

// Where each run of the sweep sits in the report (the campaign page's per-scene drill-down).
struct CampaignRun {
  std::string run;  // the sweep's run label
  std::string scene;
  double level_deg = 0.0;
  std::string status;
};

struct FailedRun {
  std::string run;  // the sweep's run label
  std::string scene;
  double level_deg = 0.0;
  std::string error;
};

// The paper's Table 4 (§4.5, downstream 3DGS on held-out views): one row per pose source of one
// splat stage, trainer and perturbation level. Each scene's value is the mean over its runs'
// successful trainings (seeds pooled); the row is the mean over the scenes that have one, so a
// row with fewer scenes than its table's others is not comparable with them (`scenes` says).
struct SplatCell {
  std::string stage_id;  // "splat", "splat@gsplat"
  std::string trainer;   // gsplat, inria, nerfstudio: never pooled, their numbers differ in kind
  double level_deg = 0.0;
  std::string scene;       // display name; CampaignReport::kAllScenes for the mean over scenes
  std::string pose_set;    // the pose source
  int scenes = 0;          // scenes with a successful training (1 or 0 for a scene's own cell)
  int scenes_tried = 0;    // scenes where it was trained at all, successfully or not
  int trainings = 0;       // successful trainings
  int failed = 0;          // failed trainings (`splat_failed`): counted, never scored
  double psnr = kNoValue;  // the trainer's held-out metrics, dB
  double ssim = kNoValue;
  double lpips = kNoValue;         // NaN when the trainer reported none
  double raytime_psnr = kNoValue;  // raytime's own over the trainer's renders (image_metrics.h)
  double raytime_ssim = kNoValue;
  // The training-noise floor (§4.5): the largest minus the smallest raytime PSNR of the scene's
  // trainings of this pose set (runs that differ in their seed, typically), dB; over scenes, the
  // largest scene's. NaN with fewer than two scored trainings.
  double seed_spread_psnr = kNoValue;
  double median_seconds = kNoValue;  // the trainer's wall time per training (model)
};

struct CampaignReport {
  static constexpr const char* kAllScenes = "(all)";

  CampaignReportOptions options;
  int total_runs = 0;               // rows, failed ones included
  bool level_swept = true;          // false: no row has options.level_key (every level reads 0)
  std::vector<std::string> scenes;  // display names, first-seen order
  std::vector<double> levels;       // ascending
  std::vector<std::string> arms;    // prior, bootstrap, refined*, classical*, mappers, others
  // Swept keys other than the scene and the level (seeds, typically) with their distinct value
  // counts: a cell pools runs that differ in these.
  std::vector<std::pair<std::string, int>> pooled_keys;
  std::vector<CampaignCell> cells;     // per scene, then pooled over scenes
  std::vector<FailedRun> failed_runs;  // status != "ok": counted, never scored
  std::vector<CampaignRun> runs;       // every row, in the sweep's order
  // Table 4 cells of the successful runs' splat stages: per scene, then kAllScenes; by stage,
  // trainer, level, then pose source in report order (prior first, ground_truth last).
  std::vector<SplatCell> splat_cells;

  // nullptr when no run of that scene and level scored the arm.
  const CampaignCell* Find(const std::string& scene, double level_deg,
                           const std::string& arm) const;
  // Failed runs of a scene (kAllScenes: of every scene) at a level.
  int FailedRunsAt(const std::string& scene, double level_deg) const;
};

// Aggregates sweep rows. A run that did not succeed (status other than "ok" or
// "ok_with_warnings") is listed in failed_runs and not scored; a level that is not a number is an
// InputError naming the run.
CampaignReport AggregateCampaign(const std::vector<SweepRow>& rows,
                                 const CampaignReportOptions& options = {});

// The Markdown report; `source` names the sweep in its header.
std::string CampaignReportMarkdown(const CampaignReport& report, const std::string& source);

// One row per cell (scene, level, arm; scene kAllScenes for the pooled cells) with every
// aggregate number, Wilson intervals included; empty fields for NaN.
std::string CampaignCellsCsv(const CampaignReport& report);

// One row per Table 4 cell (splat_cells); "" when the sweep trained no 3DGS.
std::string CampaignSplatCsv(const CampaignReport& report);

}  // namespace raytime
