// The `evaluate` (any two pose files) and `report` (a finished sweep's campaign report)
// subcommands (issue 31: cli/ reaches the stages only through pipelines/, so their work is here).
#pragma once

#include <string>

#include "report/campaign_report.h"

namespace raytime {

// `raytime evaluate --est FILE --gt FILE`: scores one pose file against another joined by image
// name (format "hdf5" reads pose set `*_set`, or the only one there), prints a table or, with
// `as_json`, the PoseErrorSummary as JSON on stdout. Returns the exit status.
int RunEvaluateCommand(const std::string& est, const std::string& est_format,
                       const std::string& est_set, const std::string& gt,
                       const std::string& gt_format, const std::string& gt_set,
                       const std::string& align, double success_deg, bool as_json);

// `raytime report --sweep W`: W/sweep.json -> OUT/report.md, OUT/report_cells.csv,
// OUT/report_splat.csv (when the sweep trained 3DGS) and the plots (SPEC §6 campaigns, §7; paper
// §4.5, §4.8, §4.9); `out_dir` "" = the sweep directory. Returns the exit status.
int RunReportCommand(const std::string& sweep_dir, std::string out_dir,
                     const CampaignReportOptions& options);

// `raytime score-splat --ply P --data D --out O`: renders the held-out cameras of the 3dgs export D
// (test.txt) from any trainer's .ply as that trainer rasterizes (SplatRenderOptionsOf), writes
// O/renders and O/gt, prints {"num_images", "psnr", "ssim"} on stdout (issue 33). Returns the exit
// status.
int RunScoreSplatCommand(const std::string& ply, const std::string& data_dir,
                         const std::string& out_dir, const std::string& trainer, double downscale);

}  // namespace raytime
