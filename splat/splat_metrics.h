// What the 3DGS trainers write about their held-out views (SPEC §7; paper §4.5, Table 4), read
// back from a trainer's result folder. The formats, as the trainers write them:
//
//   gsplat      RESULT/stats/val_step{step:04d}.json   {"psnr", "ssim", "lpips", "ellipse_time",
//               (examples/simple_trainer.py)            "num_GS", ...}; one per eval step (0-based:
//                                                      7k steps -> val_step6999.json)
//               RESULT/renders/val_step{step}_{i:04d}.png   [ground truth | render] side by side
//   inria       MODEL/results.json (metrics.py)        {"ours_30000": {"SSIM", "PSNR", "LPIPS"}}
//               MODEL/test/ours_<it>/{renders,gt}/NNNNN.png (render.py)
//   nerfstudio  ns-eval --output-path FILE             {"experiment_name", "method_name",
//                                                       "checkpoint", "results": {"psnr", "ssim",
//                                                       "lpips", "psnr_std", ..., "fps"}}
//               ns-eval --render-output-path DIR       DIR/eval_img_{i:04d}.png, [ground truth |
//                                                      render] side by side
//
// The trainer hook (splat/splat_trainer.h) fixes where the nerfstudio files go:
// RESULT/eval.json and RESULT/eval_renders/.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "splat/image_metrics.h"

namespace raytime {

// OpenSplat writes no metrics of its own: raytime renders and scores its .ply (splat_trainer.h).
inline const std::vector<std::string> kSplatTrainers = {"gsplat", "inria", "nerfstudio",
                                                        "opensplat"};

// A trainer's own numbers for its held-out views; NaN / -1 where it does not report one.
struct TrainerMetrics {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::string file;   // the file read
  int64_t step = -1;  // the training step (gsplat, nerfstudio) or iteration (inria) they belong to
  double psnr = kNone;         // dB
  double ssim = kNone;         // in [-1, 1]
  double lpips = kNone;        // >= 0; absent when the trainer did not compute it
  int64_t num_gaussians = -1;  // gsplat's num_GS
};

// RESULT/stats/val_step<N>.json with the highest N (by number, not by name). InputError naming the
// folder or file when none exists, the JSON does not parse (Python writes NaN and Infinity, which
// JSON has not: a diverged training), or psnr / ssim are missing or out of range.
TrainerMetrics ReadGsplatStats(const std::string& result_dir);

// MODEL/results.json: the entry "ours_<N>" with the highest N. InputError as above.
TrainerMetrics ReadInriaResults(const std::string& model_dir);

// ns-eval's output file: its "results"; the step from the checkpoint's name (step-<N>.ckpt) when
// it has one. InputError as above.
TrainerMetrics ReadNerfstudioEval(const std::string& path);

// The reader of `trainer` (one of kSplatTrainers) on its result folder; nerfstudio's file is
// RESULT/eval.json.
TrainerMetrics ReadTrainerMetrics(const std::string& trainer, const std::string& result_dir);

// The held-out renders a trainer left in its result folder for raytime's own metrics, those of
// the step `metrics` reports: gsplat's RESULT/renders/val_step<step>_*.png, Inria's
// MODEL/test/ours_<it>/{renders,gt}/, nerfstudio's RESULT/eval_renders/eval_img_*.png. None (and
// `absent_reason` says why) when the trainer did not save them.
std::vector<HeldOutView> TrainerHeldOutViews(const std::string& trainer,
                                             const std::string& result_dir,
                                             const TrainerMetrics& metrics,
                                             std::string* absent_reason);

}  // namespace raytime
