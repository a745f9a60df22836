// The 3DGS trainer hook (SPEC §7; paper §4.5, Table 4): an external trainer (gsplat, the Inria
// reference code, nerfstudio's splatfacto, OpenSplat) run by a shell command on one trainer-ready
// export of a pose set, its held-out metrics read back (splat/splat_metrics.h) and its held-out
// renders scored by raytime itself (splat/image_metrics.h). OpenSplat (issue 33) trains on a
// train-only view of the export and writes only its .ply: raytime renders the held-out cameras
// from it (splat/held_out_render.h) and scores those.
//
// The command is a template: {data_dir} (the export, WORKDIR/3dgs/<pose set>), {result_dir} (the
// trainer's output folder, emptied first), {pose_set}, {train_dir} (RESULT/train_view: the
// export's model without its held-out images, written when the command uses it), {steps},
// {downscale}, {seed} and {binary} are replaced by their values, absolute and shell-quoted where
// needed (write them unquoted). It runs under /bin/sh in its own process
// group, with stdout and stderr in a log file; a timeout or an interruption stops the whole group
// (a trainer's data-loader workers included). A non-zero exit, a timeout or a metrics file that
// is missing or does not read is a failed run, reported with the log's last lines, never a
// number.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/options.h"
#include "splat/splat_metrics.h"

namespace raytime {

struct SplatTrainerOptions {
  // Which trainer's output layout and metrics files to read (kSplatTrainers).
  std::string trainer = "gsplat";
  // Shell command template; empty runs the trainer's usual command line (DefaultSplatCommand).
  std::string command;
  // Where the command runs, e.g. the trainer's checkout (gsplat's and Inria's default commands
  // run scripts by relative path); empty: the directory raytime runs in.
  std::string working_dir;
  // Seconds before the trainer is stopped and the run counted as failed; 0: no limit.
  double timeout_s = 0.0;
  // Training steps ({steps}; OpenSplat's -n). 30000: the paper's protocol (§4.5); a CPU protocol
  // takes far fewer (configs/splat_benchmark.yaml).
  int steps = 30000;
  // Image downscale factor ({downscale}; OpenSplat's -d), and the size raytime renders the
  // held-out views at (photo size / downscale).
  double downscale = 1.0;
  // {seed}, for commands whose trainer takes one; also the order of the train-only view's images
  // (WriteTrainOnlyView): OpenSplat 1.1.5 has no seed option and seeds itself with 42, so two
  // seeds of one pose set differ by the order it visits the cameras.
  int seed = 0;
  // The train-only view's initial points: 0 the export's (each pose set's own tracks); N > 0, N
  // random points in a ball around the training cameras: one draw per seed, placed by each pose
  // set's own cameras (the paper's random initialization, §4.5: no pose source favoured).
  int random_init_points = 0;
  // {binary}: the trainer's executable in the default command (opensplat: found on PATH when
  // empty; scripts/install_opensplat.sh puts it there).
  std::string binary;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("trainer", trainer,
      "3DGS trainer whose output layout and metrics files are read (gsplat, inria, nerfstudio; "
      "opensplat: trained on the training frames, scored by raytime's own render)",
      OneOf(kSplatTrainers));
    v("command", command,
      "Shell command per pose set; {data_dir}, {result_dir}, {pose_set}, {train_dir}, {steps}, "
      "{downscale}, {seed}, {binary} are replaced (unquoted); empty: the trainer's usual command "
      "(README, 'Train 3DGS on the result')");
    v("working_dir", working_dir,
      "Directory the command runs in, e.g. the trainer's checkout (empty: raytime's)");
    v("timeout_s", timeout_s, "Stop a trainer after this many seconds, a failure (0: no limit)",
      NonNegative(), AtMost(1e7));
    v("steps", steps, "Training steps, the command's {steps} (opensplat: -n)", Positive(),
      AtMost(1e8));
    v("downscale", downscale,
      "Image downscale factor, the command's {downscale} (opensplat: -d); held-out views are "
      "rendered at the photos' size over it",
      AtLeast(1.0), AtMost(1000));
    v("seed", seed,
      "The command's {seed}; also shuffles the train-only view's image order (0: as exported)",
      NonNegative());
    v("random_init_points", random_init_points,
      "Initial points of the train-only view: 0 the export's, N random ones in a ball around the "
      "training cameras (the paper's random initialization)",
      NonNegative(), AtMost(1e8));
    v("binary", binary,
      "The trainer's executable in the default command, {binary} (empty: 'opensplat' on PATH)");
  }
  // A "{name}" that is not a placeholder is a typo (shell "${name}" is left alone).
  void CheckRelations(const Requirement& require) const;
};

// The trainer's usual command line, with the placeholders (README "Train 3DGS on the result").
std::string DefaultSplatCommand(const std::string& trainer);

// One pose set's run.
struct SplatJob {
  std::string pose_set;
  std::string data_dir;    // the export; made absolute
  std::string result_dir;  // made absolute; emptied before the trainer runs
  std::string log_path;    // stdout and stderr of the command, truncated first
  // Read an earlier run's result folder instead of running the trainer again.
  bool reuse_result = false;
};

// `command` (or the trainer's default) with the job's values in place of the placeholders.
std::string ExpandSplatCommand(const SplatTrainerOptions& options, const SplatJob& job);

struct SplatRunSummary {
  std::string pose_set;
  std::string trainer;
  std::string status;   // "ok" or "failed"
  std::string error;    // why it failed; "" when ok
  bool reused = false;  // an earlier run's result folder was read, the trainer did not run
  std::string command;  // as run, placeholders replaced
  std::string data_dir;
  std::string result_dir;
  std::string log_path;
  double seconds = 0.0;  // the command's wall time (0 when reused)
  int exit_code = -1;    // -1: killed by a signal, timed out, or did not run
  int signal = 0;
  bool timed_out = false;
  std::string log_tail;  // the log's last lines when the run failed
  // The trainer's build: OpenSplat's commit (scripts/install_opensplat.sh records it beside the
  // binary), "" when unknown.
  std::string trainer_version;
  // The trainer's own numbers (NaN when absent; JSON null).
  std::string metrics_file;
  int64_t step = -1;
  double psnr = TrainerMetrics::kNone;
  double ssim = TrainerMetrics::kNone;
  double lpips = TrainerMetrics::kNone;
  int64_t num_gaussians = -1;
  // raytime's own PSNR / SSIM over the trainer's held-out renders (image_metrics.h); NaN and the
  // reason in raytime_note when the trainer left none or they do not read.
  int raytime_images = 0;
  double raytime_psnr = TrainerMetrics::kNone;
  double raytime_ssim = TrainerMetrics::kNone;
  std::string raytime_note;

  bool ok() const { return status == "ok"; }
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(SplatRunSummary, pose_set, trainer, status, error, reused,
                                   command, data_dir, result_dir, log_path, seconds, exit_code,
                                   signal, timed_out, log_tail, trainer_version, metrics_file, step,
                                   psnr, ssim, lpips, num_gaussians, raytime_images, raytime_psnr,
                                   raytime_ssim, raytime_note)

// Runs the trainer on one export (or, with reuse_result, only reads its earlier result) and
// scores it. A failed trainer is a summary with status "failed", not an exception; InputError
// only for what stops every pose set alike (the working directory does not exist).
SplatRunSummary RunSplatTrainer(const SplatTrainerOptions& options, const SplatJob& job);

}  // namespace raytime
