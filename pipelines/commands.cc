#include "pipelines/commands.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/process.h"
#include "core/shipped_files.h"
#include "core/timing.h"
#include "evaluate/pose_errors.h"
#include "formats/dataset.h"
#include "report/campaign_page.h"
#include "report/html.h"
#include "report/run_report.h"
#include "report/sweep_row.h"
#include "splat/held_out_render.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// Campaign plots are drawn by scripts/plot_campaign.py (matplotlib), found in RAYTIME_SCRIPT_DIR,
// the installed share/raytime/scripts or the source tree this binary was built from
// (core/shipped_files.h).
constexpr const char* kPython = "/usr/bin/python3";
constexpr int kPlotExitNoMatplotlib = 3;  // plot_campaign.py: matplotlib is not installed
// How `raytime evaluate` names one pose set of an HDF5 file holding several.
constexpr const char* kChooseSet = "with --est-set/--gt-set";

}  // namespace

int RunEvaluateCommand(const std::string& est, const std::string& est_format,
                       const std::string& est_set, const std::string& gt,
                       const std::string& gt_format, const std::string& gt_set,
                       const std::string& align, double success_deg, bool as_json) {
  PoseErrorOptions options;
  options.alignment = align;
  options.success_rotation_deg = success_deg;
  const PoseErrorSummary errors =
      ComputePoseErrors(ReadPoseFileOrSet(est_format, est, est_set, kChooseSet),
                        ReadPoseFileOrSet(gt_format, gt, gt_set, kChooseSet), options);
  if (as_json) {
    std::cout << errors.ToJson().dump(2) << "\n";
    return 0;
  }
  std::printf("%-24s %12s %12s\n", "frame", "rot [deg]", "centre [m]");
  for (const auto& frame : errors.frames) {
    std::printf("%-24s %12.5f %12.5f\n", frame.name.c_str(), frame.rotation_deg, frame.centre_m);
  }
  std::printf(
      "alignment %s, %d frames: rotation mean %.5f median %.5f deg; centre mean %.5f "
      "median %.5f m; success (< %.2f deg): %s\n"
      "relative rotation (no alignment), %d pairs: mean %.5f median %.5f deg\n",
      errors.alignment.c_str(), errors.num_frames, errors.mean_rotation_deg,
      errors.median_rotation_deg, errors.mean_centre_m, errors.median_centre_m, success_deg,
      errors.success ? "yes" : "no", errors.num_relative_pairs, errors.mean_relative_rotation_deg,
      errors.median_relative_rotation_deg);
  if (errors.alignment != "none") {
    std::printf(
        "the alignment's own rotation, RMS from the centres left after it: %.5f deg (rotation "
        "errors that differ by less are not told apart)\n",
        errors.alignment_rotation_sigma_deg);
  }
  for (const auto& name : errors.only_in_estimate) {
    std::printf("not scored: %s has no ground truth\n", name.c_str());
  }
  for (const auto& name : errors.only_in_ground_truth) {
    std::printf("not scored: %s is missing from the estimate\n", name.c_str());
  }
  return 0;
}

int RunScoreSplatCommand(const std::string& ply, const std::string& data_dir,
                         const std::string& out_dir, const std::string& trainer, double downscale) {
  HeldOutRenderOptions options;
  options.downscale = downscale;
  options.render = SplatRenderOptionsOf(trainer);
  const auto start = std::chrono::steady_clock::now();
  const GaussianSplats splats = ReadGaussianSplatPly(ply);
  const size_t broken = CountNonFiniteGaussians(splats);
  if (broken > 0) {
    spdlog::warn(fmt::format(
        "score-splat: {} of {} Gaussians in {} are not finite (dropped from the renders): a "
        "diverged or broken training",
        broken, splats.size(), ply));
  }
  const HeldOutScore score = RenderAndScoreHeldOutViews(splats, data_dir, out_dir, options);
  spdlog::info(fmt::format("score-splat: {} held-out view(s) rendered in {:.2f} s into {}/renders",
                           score.num_images, SecondsSince(start), out_dir));
  std::printf("%s\n", nlohmann::json({{"num_images", score.num_images},
                                      {"non_finite_gaussians", broken},
                                      {"psnr", score.psnr},
                                      {"ssim", score.ssim}})
                          .dump()
                          .c_str());
  return 0;
}

// Per run label of the sweep (WORKDIR/runs.json), the link from `out_dir` to its page; a run that
// finished before runs wrote pages gets one written now (a page that cannot be is left out).
std::map<std::string, std::string> RunPageLinks(const std::string& sweep_dir,
                                                const std::string& out_dir) {
  std::map<std::string, std::string> links;
  const fs::path list_path = fs::path(sweep_dir) / "runs.json";
  if (!fs::exists(list_path)) return links;
  const nlohmann::json list =
      nlohmann::json::parse(ReadTextFile(list_path.string()), nullptr, false);
  if (!list.is_array()) return links;
  for (const nlohmann::json& run : list) {
    const std::string label = JsonText(run, "label"), dir = JsonText(run, "dir");
    if (label.empty() || dir.empty()) continue;
    const fs::path page = fs::path(dir) / "report.html";
    if (!fs::exists(page) && fs::exists(fs::path(dir) / "summary.json")) {
      try {
        WriteRunReport(dir);
      } catch (const std::exception& e) {
        spdlog::warn(fmt::format("report: no page for run {}: {}", label, e.what()));
      }
    }
    if (fs::exists(page)) {
      links[label] = fs::relative(fs::absolute(page), fs::absolute(out_dir)).generic_string();
    }
  }
  return links;
}

int RunReportCommand(const std::string& sweep_dir, std::string out_dir,
                     const CampaignReportOptions& options) {
  const std::string sweep_path = (fs::path(sweep_dir) / "sweep.json").string();
  if (!fs::exists(sweep_path)) {
    ThrowInput(sweep_path, 0,
               "no such file; `raytime run PIPELINE.yaml --workdir DIR` writes it for a pipeline "
               "with a sweep section");
  }
  const std::vector<SweepRow> rows = ReadSweepRows(sweep_path);
  CampaignReport report;
  try {
    report = AggregateCampaign(rows, options);
  } catch (const InputError& e) {
    ThrowInput(sweep_path, 0, e.what());
  }
  if (out_dir.empty()) out_dir = sweep_dir;
  fs::create_directories(out_dir);
  const std::string markdown_path = (fs::path(out_dir) / "report.md").string();
  const std::string cells_path = (fs::path(out_dir) / "report_cells.csv").string();
  WriteTextFileAtomically(markdown_path, CampaignReportMarkdown(report, sweep_path));
  WriteTextFileAtomically(cells_path, CampaignCellsCsv(report));
  const std::string page_path = (fs::path(out_dir) / "report.html").string();
  WriteTextFileAtomically(
      page_path, CampaignReportHtml(report, rows, RunPageLinks(sweep_dir, out_dir), sweep_path));
  spdlog::info(fmt::format("report: the campaign page {}", page_path));
  spdlog::info(
      fmt::format("report: {} runs ({} failed), {} scene(s), {} level(s), {} arm(s): {}, {}",
                  report.total_runs, report.failed_runs.size(), report.scenes.size(),
                  report.levels.size(), report.arms.size(), markdown_path, cells_path));
  // Table 4's cells, when the sweep trained 3DGS (splat stages).
  const std::string splat_path = (fs::path(out_dir) / "report_splat.csv").string();
  if (!report.splat_cells.empty()) {
    WriteTextFileAtomically(splat_path, CampaignSplatCsv(report));
    spdlog::info(fmt::format("report: downstream 3DGS (Table 4) cells: {}", splat_path));
  }

  if (!fs::exists(kPython)) {
    spdlog::warn(fmt::format("report: {} not found, no plots written", kPython));
    return 0;
  }
  const ShippedDirectory scripts = FindShippedDirectory("RAYTIME_SCRIPT_DIR", "scripts");
  const std::string script = (scripts.path / "plot_campaign.py").string();
  if (scripts.path.empty() || !fs::exists(script)) {
    spdlog::warn(
        fmt::format("report: plot script plot_campaign.py not found in {}, no plots written",
                    scripts.Searched()));
    return 0;
  }
  const ProcessStatus status = RunProcess({kPython, script, cells_path, out_dir});
  if (status.exit_code == kPlotExitNoMatplotlib) {
    spdlog::warn(
        "report: matplotlib is missing, no plots written (report.md and "
        "report_cells.csv are complete)");
  } else if (!status.Succeeded()) {
    throw std::runtime_error("report: " + script + " failed (" + status.Describe() + "); " +
                             markdown_path + " and " + cells_path + " were written");
  } else {
    spdlog::info(fmt::format(
        "report: plots success_vs_level and median_error_vs_level (.png, .svg) in {}", out_dir));
  }
  return 0;
}

}  // namespace raytime
