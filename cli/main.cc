// The `raytime` command line: `run` for YAML pipelines, one subcommand per stage, `evaluate` on
// any two pose files, `report` on a finished sweep, and `resize-scene` for making small sample
// scenes.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <malloc.h>

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "cli/progress_log_sink.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/interrupt.h"
#include "core/version.h"
#include "pipelines/commands.h"
#include "pipelines/pipeline.h"
#include "pipelines/resize_scene.h"
#include "pipelines/run_report.h"
#include "pipelines/stage.h"
#include "pipelines/sweep.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// `raytime <stage> --in A.h5 --in B.h5 --out OUT.h5 [--option value ...]`.
CLI::App* AddStageCommand(CLI::App& app, const std::string& type, std::vector<std::string>* inputs,
                          std::string* output, std::unique_ptr<Stage>* holder) {
  *holder = CreateStage(type);
  CLI::App* command = app.add_subcommand(
      type, (*holder)->description() +
                " (one stage alone: reads --in HDF5 files, writes --out, prints its summary JSON "
                "on stdout; logs go to stderr)");
  command->add_option("--in", *inputs,
                      "HDF5 files from earlier stages (artifacts are looked up "
                      "in them, later files win)");
  command->add_option("--out", *output, "HDF5 file to write (default: ./<stage>.h5)");
  (*holder)->BindCli(command->add_option_group("options", "The stage's options"));
  return command;
}

// Only the summary JSON goes to stdout, so `raytime STAGE ... | jq` works.
int RunStageAlone(Stage& stage, const std::vector<std::string>& inputs, std::string output) {
  if (output.empty()) output = stage.type() + ".h5";
  StageContext context;
  context.output_path = output;
  context.workdir = fs::path(output).parent_path().string();
  if (context.workdir.empty()) context.workdir = ".";
  for (const auto& input : inputs) {
    const Hdf5Reader reader(input);
    if (reader.HasImages()) context.artifacts[kArtifactImages] = input;
    for (const auto& name : reader.PoseSetNames()) context.artifacts[PoseArtifact(name)] = input;
    if (reader.HasFeatures()) context.artifacts["features"] = input;
    if (reader.HasMatches()) context.artifacts["matches"] = input;
  }
  RemoveStaleTemporaryFiles(context.workdir);
  const nlohmann::json summary = stage.Run(context);
  LogWarnings(stage.type(), summary);
  std::cout << summary.dump(2) << "\n";
  return 0;
}

// `raytime run PIPELINE.yaml`.
struct RunCommand {
  std::string pipeline_path, workdir;
  std::vector<std::string> overrides;
  bool force = false;
  bool no_report = false;
  RunOptions run_options;
  CLI::App* command = nullptr;
  CLI::Option* workdir_option = nullptr;

  void Add(CLI::App& app) {
    command =
        app.add_subcommand("run", "Run a YAML pipeline (resumes: unchanged stages are skipped)");
    command->add_option("pipeline", pipeline_path, "Pipeline YAML file")->required();
    workdir_option = command->add_option("--workdir", workdir,
                                         "Work directory (overrides the pipeline's 'workdir')");
    command->add_option("--set", overrides, "Override an option: STAGE.KEY=VALUE (repeatable)");
    command->add_flag("--force", force, "Rerun every stage even when unchanged");
    command->add_option("--jobs", run_options.jobs,
                        "Concurrent sweep runs (default: number of cores)");
    command->add_option("--cache_dir,--cache-dir", run_options.cache_dir,
                        "Stage outputs shared between runs, by content key (sweeps default to "
                        "WORKDIR/cache)");
    command
        ->add_option("--backend", run_options.backend,
                     "Where a sweep's runs execute: processes on this machine, or job arrays on a "
                     "Slurm cluster (work directory and cache on a path every node sees)")
        ->check(CLI::IsMember({"local", "slurm"}))
        ->capture_default_str();
    command->add_option("--partition", run_options.partition,
                        "Slurm partition of the sweep's jobs (default: the cluster's)");
    command->add_flag("--wait", run_options.slurm_wait,
                      "Slurm backend: wait until every run has ended and the tables are collected");
    command->add_flag("--no_report,--no-report", no_report,
                      "After a sweep, do not write the campaign report (WORKDIR/report.md, plots)");
  }

  int Execute() {
    // An empty --workdir (an unset shell variable, say) would quietly write into the pipeline's.
    if (workdir_option->count() > 0 && workdir.empty()) {
      throw InputError(
          "raytime run: --workdir is empty; give a directory, or leave the option "
          "out to use the pipeline's 'workdir'");
    }
    PipelineSpec spec = LoadPipeline(pipeline_path);
    for (const auto& assignment : overrides) ApplyOverride(&spec, assignment);
    run_options.workdir = workdir;
    run_options.force = force;
    // A sweep ends with its campaign report, so one command reproduces a ladder's tables and
    // plots; failed runs are listed in it, and the failure is still the exit status.
    const std::string effective_workdir = workdir.empty() ? spec.workdir : workdir;
    // With the Slurm backend the collect job writes the report (unless the sweep is awaited).
    const bool report_after = !spec.sweep.empty() && !no_report &&
                              (run_options.backend == "local" || run_options.slurm_wait);
    try {
      RunPipeline(spec, run_options);
    } catch (...) {
      if (report_after && fs::exists(fs::path(effective_workdir) / "sweep.json")) {
        RunReportCommand(effective_workdir, "", CampaignReportOptions());
      }
      throw;
    }
    if (report_after) return RunReportCommand(effective_workdir, "", CampaignReportOptions());
    return 0;
  }
};

// `raytime evaluate --est ... --gt ...`: any two pose files (HDF5 included), beside the stage.
struct EvaluateFilesCommand {
  std::string est, est_format = "colmap", est_set, gt, gt_format = "strecha", gt_set,
                   align = "sim3";
  double success_deg = 1.0;
  bool as_json = false;
  CLI::App* command = nullptr;
  CLI::Option* est_option = nullptr;
  CLI::Option* gt_option = nullptr;

  void Add(CLI::App* evaluate) {
    command = evaluate;
    evaluate->description(
        "Score pose sets against ground truth: the stage (--in/--out and the stage's options), or "
        "any two pose files joined by image name (--est/--gt)");
    CLI::Option_group* files = evaluate->add_option_group(
        "pose files", "Score two pose files instead of running the stage (needs --est and --gt)");
    est_option = files->add_option("--est", est, "Estimated poses (file or folder)");
    files
        ->add_option("--est_format,--est-format", est_format,
                     "A pose file format (prior.format) or hdf5")
        ->capture_default_str();
    files->add_option("--est_set,--est-set", est_set, "Pose set name in an HDF5 file");
    gt_option = files->add_option("--gt", gt, "Ground-truth poses (file or folder)");
    files
        ->add_option("--gt_format,--gt-format", gt_format,
                     "A pose file format (prior.format) or hdf5")
        ->capture_default_str();
    files->add_option("--gt_set,--gt-set", gt_set, "Pose set name in an HDF5 file");
    files->add_option("--align", align, "sim3, se3 or none")->capture_default_str();
    files
        ->add_option("--success_deg,--success-deg", success_deg,
                     "Success threshold on the mean rotation error, degrees")
        ->capture_default_str();
    files->add_flag("--json", as_json, "Print JSON instead of a table");
  }

  bool Parsed() const {
    return command->parsed() && (est_option->count() > 0 || gt_option->count() > 0);
  }

  int Execute() const {
    if (est.empty() || gt.empty()) {
      throw InputError("raytime evaluate: scoring pose files needs both --est and --gt");
    }
    return RunEvaluateCommand(est, est_format, est_set, gt, gt_format, gt_set, align, success_deg,
                              as_json);
  }
};

// `raytime report --sweep DIR` (a campaign) or `raytime report --run WORKDIR` (one run's page).
struct ReportCommand {
  std::string sweep_dir, report_dir, run_dir;
  CampaignReportOptions report_options;
  bool collect = false;
  CLI::App* command = nullptr;

  void Add(CLI::App& app) {
    command = app.add_subcommand(
        "report",
        "Campaign report of a finished sweep: Markdown tables shaped like the paper's "
        "Tables 5, 6 and 8 (and 4 when it trained 3DGS), CSVs of cells, plots");
    CLI::Option* sweep =
        command->add_option("--sweep", sweep_dir, "Sweep work directory (reads DIR/sweep.json)");
    CLI::Option* run = command->add_option(
        "--run", run_dir, "A run's work directory: rebuild its page WORKDIR/report.html");
    sweep->excludes(run);
    command->add_option("--out", report_dir, "Output directory (default: the sweep directory)");
    command->add_flag("--collect", collect,
                      "First rebuild DIR/sweep.csv, sweep.json and summary.json from the runs' "
                      "summaries (what the Slurm backend's last job does)");
    command
        ->add_option("--success_deg,--success-deg", report_options.success_rotation_deg,
                     "Success threshold on the mean Sim(3) rotation error, degrees")
        ->capture_default_str();
    command
        ->add_option("--scene_key,--scene-key", report_options.scene_key,
                     "Swept column naming the scene")
        ->capture_default_str();
    command
        ->add_option("--level_key,--level-key", report_options.level_key,
                     "Swept column holding the perturbation level, degrees")
        ->capture_default_str();
    command
        ->add_option("--baseline", report_options.baseline_arm,
                     "Arm the \"halves the prior's rotation error\" count compares against")
        ->capture_default_str();
  }

  int Execute() const {
    if (!run_dir.empty()) {
      spdlog::info(fmt::format("report: {}", WriteRunReport(run_dir)));
      return 0;
    }
    if (sweep_dir.empty()) throw InputError("raytime report: give --sweep DIR or --run WORKDIR");
    if (collect) CollectSweep(sweep_dir);
    return RunReportCommand(sweep_dir, report_dir, report_options);
  }
};

// `raytime resize-scene`.
struct ResizeSceneCommand {
  DatasetOptions input;
  ResizeSceneOptions options;
  std::string output;
  CLI::App* command = nullptr;

  void Add(CLI::App& app) {
    command = app.add_subcommand("resize-scene",
                                 "Write a downsampled copy of a dataset in the Strecha layout");
    command->add_option("--format", input.format, "Input dataset format")->capture_default_str();
    command->add_option("--root", input.root, "Input dataset root")->required();
    command->add_option("--out", output, "Output scene folder")->required();
    command->add_option("--width", options.width, "Output width, pixels")->capture_default_str();
    command
        ->add_option("--jpeg_quality,--jpeg-quality", options.jpeg_quality,
                     "JPEG quality of the written images, 0-100 (OpenCV's IMWRITE_JPEG_QUALITY)")
        ->check(CLI::Range(0, 100))
        ->capture_default_str();
  }

  int Execute() const {
    const int count = ResizeScene(input, output, options);
    spdlog::info(fmt::format("resize-scene: wrote {} images to {}", count, output));
    return 0;
  }
};

struct ScoreSplatCommand {
  std::string ply, data_dir, out_dir, trainer = "opensplat";
  double downscale = 1.0;
  CLI::App* command = nullptr;

  void Add(CLI::App& app) {
    command = app.add_subcommand(
        "score-splat",
        "Render a trained 3DGS .ply at a 3dgs export's held-out cameras and score them (PSNR, "
        "SSIM)");
    command->add_option("--ply", ply, "The trainer's .ply (standard 3DGS fields)")->required();
    command->add_option("--data", data_dir, "The 3dgs export (WORKDIR/3dgs/<pose set>)")
        ->required();
    command->add_option("--out", out_dir, "Where renders/ and gt/ are written")->required();
    command
        ->add_option("--trainer", trainer,
                     "Rasterize as this trainer does (gsplat, inria, nerfstudio, opensplat)")
        ->capture_default_str();
    command
        ->add_option("--downscale", downscale,
                     "The trainer's image downscale factor: render at photo size / downscale")
        ->check(CLI::Range(1.0, 1e6))
        ->capture_default_str();
  }
  int Execute() const { return RunScoreSplatCommand(ply, data_dir, out_dir, trainer, downscale); }
};

// `raytime <stage>` for every stage type.
struct StageCommands {
  std::map<std::string, std::unique_ptr<Stage>> stages;
  std::map<std::string, CLI::App*> commands;
  std::vector<std::string> inputs;
  std::string output;

  void Add(CLI::App& app) {
    for (const auto& type : StageTypes()) {
      commands[type] = AddStageCommand(app, type, &inputs, &output, &stages[type]);
    }
  }

  int Execute(const CLI::App& app) {
    for (auto& [type, stage] : stages) {
      if (app.got_subcommand(type)) {
        stage->Configure(stage->CliOptions(), "raytime " + type);
        return RunStageAlone(*stage, inputs, output);
      }
    }
    return 0;
  }
};

int Main(int argc, char** argv) {
  CLI::App app{"raytime: triangulation-free bundle adjustment from coarse pose priors"};
  app.set_version_flag("--version", std::string(Version()));
  app.require_subcommand(1);
  bool quiet = false;
  app.add_flag("-q,--quiet", quiet, "Only print warnings and errors");
  RunCommand run;
  run.Add(app);
  StageCommands stages;
  stages.Add(app);
  EvaluateFilesCommand evaluate_files;
  evaluate_files.Add(stages.commands.at("evaluate"));
  ReportCommand report;
  report.Add(app);
  ResizeSceneCommand resize;
  resize.Add(app);
  ScoreSplatCommand score_splat;
  score_splat.Add(app);

  CLI11_PARSE(app, argc, argv);
  // Logs on stderr: stdout carries only results (a stage's summary JSON, `evaluate --json`).
  // Through ProgressLogSink: a progress bar on a terminal is erased and redrawn around each line.
  spdlog::set_default_logger(std::make_shared<spdlog::logger>(
      "raytime",
      std::make_shared<ProgressLogSink>(std::make_shared<spdlog::sinks::stderr_color_sink_mt>())));
  spdlog::set_pattern("%H:%M:%S %^%l%$ %v");
  if (quiet) spdlog::set_level(spdlog::level::warn);

  if (run.command->parsed()) return run.Execute();
  if (evaluate_files.Parsed()) return evaluate_files.Execute();
  if (report.command->parsed()) return report.Execute();
  if (resize.command->parsed()) return resize.Execute();
  if (score_splat.command->parsed()) return score_splat.Execute();
  return stages.Execute(app);
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  // Every refine pass builds its problem anew and the matcher packs descriptors per pair: blocks
  // of 1 MB to hundreds of MB, allocated and freed again and again. With glibc's defaults each came
  // from a fresh mmap (or was trimmed back to the system) and every page faulted in zeroed on first
  // touch: 8-9 % of a refine's samples were page faults. Large blocks come from the heap instead
  // and up to 1 GB of freed memory is kept for the next pass (the peak is what it was). Measured,
  // auto, 2 threads, back to back (the settings as GLIBC_TUNABLES): fountain-P11 8° refine
  // 1.74 -> 1.49 s with blocks up to 32 MB kept; the chair (24 frames) and the Record3D desk (193
  // frames), whose problems are larger, 5.5 -> 4.7 s and 50.1 -> 42.4 s more with every block
  // kept; peak memory +0-2 % (desk 1.43 GB both).
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  raytime::InstallInterruptHandler();
  try {
    const int status = raytime::Main(argc, argv);
    if (raytime::Interrupting()) raytime::AwaitInterruptExit();
    return status;
  } catch (const raytime::InputError& e) {
    if (raytime::Interrupting()) raytime::AwaitInterruptExit();
    spdlog::error(fmt::format("{}", e.what()));
    return 2;
  } catch (const std::exception& e) {
    if (raytime::Interrupting()) raytime::AwaitInterruptExit();
    spdlog::error(fmt::format("{}", e.what()));
    return 1;
  }
}
