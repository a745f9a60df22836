// The `raytime` command line: `run` for YAML pipelines, one subcommand per stage, `evaluate` on
// any two pose files, `report` on a finished sweep, and `resize-scene` for making small sample
// scenes.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <malloc.h>
#include <signal.h>

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>

#include "cli/progress_log_sink.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/interrupt.h"
#include "core/resource_failure.h"
#include "core/supervise.h"
#include "core/user_paths.h"
#include "core/version.h"
#include "pipelines/commands.h"
#include "pipelines/pipeline.h"
#include "pipelines/resize_scene.h"
#include "pipelines/stage.h"
#include "pipelines/sweep.h"
#include "report/run_report.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// A path option: its value's leading tilde expanded as a shell would (a quoted '~/wk' reaches us
// unexpanded; core/user_paths.h).
CLI::Option* PathOption(CLI::Option* option) {
  return option->transform([](std::string path) {
    try {
      return ExpandUser(path);
    } catch (const InputError& e) {
      throw CLI::ValidationError(e.what());
    }
  });
}

// `raytime <stage> --in A.h5 --in B.h5 --out OUT.h5 [--option value ...]`.
CLI::App* AddStageCommand(CLI::App& app, const std::string& type, std::vector<std::string>* inputs,
                          std::string* output, std::unique_ptr<Stage>* holder) {
  *holder = CreateStage(type);
  CLI::App* command = app.add_subcommand(
      type, (*holder)->description() +
                " (one stage alone: reads --in HDF5 files, writes --out, prints its summary JSON "
                "on stdout; logs go to stderr)");
  PathOption(command->add_option("--in", *inputs,
                                 "HDF5 files from earlier stages (artifacts are looked up "
                                 "in them, later files win)"));
  PathOption(command->add_option("--out", *output, "HDF5 file to write (default: ./<stage>.h5)"));
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

// The last non-empty line of `text`.
std::string LastLine(const std::string& text) {
  const size_t end = text.find_last_not_of('\n');
  if (end == std::string::npos) return "";
  const size_t newline = text.rfind('\n', end);
  const size_t start = newline == std::string::npos ? 0 : newline + 1;
  return text.substr(start, end - start + 1);
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
    PathOption(command->add_option("pipeline", pipeline_path, "Pipeline YAML file"))->required();
    workdir_option = PathOption(command->add_option(
        "--workdir", workdir, "Work directory (overrides the pipeline's 'workdir')"));
    command->add_option("--set", overrides, "Override an option: STAGE.KEY=VALUE (repeatable)");
    command->add_flag("--force", force, "Rerun every stage even when unchanged");
    command->add_option("--jobs", run_options.jobs,
                        "Concurrent sweep runs (default: number of cores)");
    PathOption(
        command->add_option("--cache_dir,--cache-dir", run_options.cache_dir,
                            "Stage outputs shared between runs, by content key (sweeps default to "
                            "WORKDIR/cache)"));
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

  // The pipeline file with the --set overrides applied.
  PipelineSpec Spec() const {
    PipelineSpec spec = LoadPipeline(pipeline_path);
    for (const auto& assignment : overrides) ApplyOverride(&spec, assignment);
    return spec;
  }
  // The pipeline read again by the supervising parent, which needs it only to finish a crashed
  // run's record: what the file deserves (a deprecated key's warning, say) the run has said.
  PipelineSpec SpecWithoutWarnings() const {
    const spdlog::level::level_enum level = spdlog::get_level();
    spdlog::set_level(spdlog::level::err);
    try {
      PipelineSpec spec = Spec();
      spdlog::set_level(level);
      return spec;
    } catch (...) {
      spdlog::set_level(level);
      throw;
    }
  }
  std::string EffectiveWorkdir(const PipelineSpec& spec) const {
    return workdir.empty() ? spec.workdir : workdir;
  }

  // The parent's part once the run's process has ended (core/supervise.h): a process killed by
  // a signal, or one that ended leaving its record at "running", crashed; its record is finished
  // here. Returns the exit status.
  int Ended(const SupervisedEnd& end, std::filesystem::file_time_type run_start) const {
    const bool killed = end.status.signal != 0;
    std::string message =
        killed
            ? "raytime crashed: killed by " + DescribeSignal(end.status.signal) +
                  (end.status.signal == SIGKILL ? " (the system's out-of-memory killer, or kill -9)"
                                                : "")
            : "raytime ended (exit status " + std::to_string(end.status.exit_code) +
                  ") without recording how";
    std::string cause = ResourceNamedIn(end.stderr_tail);
    const std::string last = LastLine(end.stderr_tail);
    if (!last.empty()) message += "; its last output line: \"" + last + "\"";
    if (!cause.empty()) message += ": " + ResourceAdvice(cause);
    if (cause.empty()) cause = "crash";
    if (command->parsed()) {
      try {
        const PipelineSpec spec = SpecWithoutWarnings();
        const std::string effective = EffectiveWorkdir(spec);
        if (spec.sweep.empty() && RecordCrashedRun(spec, effective, end.child, run_start, message,
                                                   cause, end.status.signal)) {
          spdlog::error(message + " (recorded in " + effective + "/summary.json)");
          return kExitCrashed;
        }
      } catch (const std::exception& e) {
        if (killed) message += " (its record could not be finished: " + std::string(e.what()) + ")";
      }
    }
    if (!killed) return end.status.exit_code;
    spdlog::error(message);
    return kExitCrashed;
  }

  int Execute() {
    // An empty --workdir (an unset shell variable, say) would quietly write into the pipeline's.
    if (workdir_option->count() > 0 && workdir.empty()) {
      throw InputError(
          "raytime run: --workdir is empty; give a directory, or leave the option "
          "out to use the pipeline's 'workdir'");
    }
    const PipelineSpec spec = Spec();
    run_options.workdir = workdir;
    run_options.force = force;
    // A sweep ends with its campaign report, so one command reproduces a ladder's tables and
    // plots; failed runs are listed in it, and the failure is still the exit status.
    const std::string effective_workdir = EffectiveWorkdir(spec);
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
    est_option = PathOption(files->add_option("--est", est, "Estimated poses (file or folder)"));
    files
        ->add_option("--est_format,--est-format", est_format,
                     "A pose file format (prior.format) or hdf5")
        ->capture_default_str();
    files->add_option("--est_set,--est-set", est_set, "Pose set name in an HDF5 file");
    gt_option = PathOption(files->add_option("--gt", gt, "Ground-truth poses (file or folder)"));
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
    CLI::Option* sweep = PathOption(
        command->add_option("--sweep", sweep_dir, "Sweep work directory (reads DIR/sweep.json)"));
    CLI::Option* run = PathOption(command->add_option(
        "--run", run_dir, "A run's work directory: rebuild its page WORKDIR/report.html"));
    sweep->excludes(run);
    PathOption(command->add_option("--out", report_dir,
                                   "Output directory (default: the sweep directory)"));
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
    PathOption(command->add_option("--root", input.root, "Input dataset root"))->required();
    PathOption(command->add_option("--out", output, "Output scene folder"))->required();
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
    PathOption(command->add_option("--ply", ply, "The trainer's .ply (standard 3DGS fields)"))
        ->required();
    PathOption(command->add_option("--data", data_dir, "The 3dgs export (WORKDIR/3dgs/<pose set>)"))
        ->required();
    PathOption(command->add_option("--out", out_dir, "Where renders/ and gt/ are written"))
        ->required();
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

// Every command, parsed once; executed in the supervised child (core/supervise.h).
class Commands {
 public:
  Commands() {
    app_.set_version_flag("--version", std::string(Version()));
    app_.require_subcommand(1);
    app_.add_flag("-q,--quiet", quiet_, "Only print warnings and errors");
    run_.Add(app_);
    stages_.Add(app_);
    evaluate_files_.Add(stages_.commands.at("evaluate"));
    report_.Add(app_);
    resize_.Add(app_);
    score_splat_.Add(app_);
  }

  // Parses the command line and sets up the log; an exit status when it ends here (--help,
  // --version: 0; a command-line error: 2, said on stderr).
  std::optional<int> Parse(int argc, char** argv) {
    try {
      app_.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      return app_.exit(e) == 0 ? kExitOk : kExitInput;
    }
    // Logs on stderr: stdout carries only results (a stage's summary JSON, `evaluate --json`).
    // Through ProgressLogSink: a progress bar on a terminal is erased and redrawn around each
    // line.
    spdlog::set_default_logger(std::make_shared<spdlog::logger>(
        "raytime", std::make_shared<ProgressLogSink>(
                       std::make_shared<spdlog::sinks::stderr_color_sink_mt>())));
    spdlog::set_pattern("%H:%M:%S %^%l%$ %v");
    if (quiet_) spdlog::set_level(spdlog::level::warn);
    return std::nullopt;
  }

  int Execute() {
    if (run_.command->parsed()) return run_.Execute();
    if (evaluate_files_.Parsed()) return evaluate_files_.Execute();
    if (report_.command->parsed()) return report_.Execute();
    if (resize_.command->parsed()) return resize_.Execute();
    if (score_splat_.command->parsed()) return score_splat_.Execute();
    return stages_.Execute(app_);
  }

  // In the supervising parent, once the child that executed the command has ended.
  int Ended(const SupervisedEnd& end, std::filesystem::file_time_type run_start) const {
    return run_.Ended(end, run_start);
  }

 private:
  CLI::App app_{"raytime: triangulation-free bundle adjustment from coarse pose priors"};
  bool quiet_ = false;
  RunCommand run_;
  StageCommands stages_;
  EvaluateFilesCommand evaluate_files_;
  ReportCommand report_;
  ResizeSceneCommand resize_;
  ScoreSplatCommand score_splat_;
};

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) {
  // Every refine pass builds its problem anew and the matcher packs descriptors per pair: blocks
  // of 1 MB to hundreds of MB, allocated and freed again and again. With glibc's defaults each came
  // from a fresh mmap (or was trimmed back to the system) and every page faulted in zeroed on first
  // touch, a large share of a refine's time. Large blocks come from the heap instead and up to
  // 1 GB of freed memory is kept for the next pass (the peak is what it was; measured:
  // docs/refine_options.md).
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  raytime::Commands commands;
  if (const std::optional<int> status = commands.Parse(argc, argv)) return *status;
  raytime::RaiseOpenFileLimit();
  const auto run_start = std::filesystem::file_time_type::clock::now();
  if (const std::optional<raytime::SupervisedEnd> end = raytime::ForkSupervised()) {
    return commands.Ended(*end, run_start);
  }
  raytime::InstallInterruptHandler();
  try {
    const int status = commands.Execute();
    if (raytime::Interrupting()) raytime::AwaitInterruptExit();
    return status;
  } catch (const std::exception& e) {
    if (raytime::Interrupting()) raytime::AwaitInterruptExit();
    const raytime::FailureDescription failure = raytime::DescribeFailure(e);
    spdlog::error(fmt::format("{}", failure.message));
    return failure.exit_code;
  }
}
