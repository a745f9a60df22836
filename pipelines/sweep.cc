#include "pipelines/sweep.h"

#include <signal.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/interrupt.h"
#include "core/process.h"
#include "core/timing.h"
#include "core/version.h"
#include "pipelines/slurm_backend.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// A sweep run in its own process: `raytime run RUN_DIR/pipeline.yaml --workdir RUN_DIR
// --cache-dir CACHE`, output to RUN_DIR/run.log. The executable is /proc/self/exe, not the path it
// links to: every run of a sweep runs the binary the sweep started with, even when a rebuild has
// replaced (unlinked) that file meanwhile.
pid_t SpawnRun(const std::string& run_dir, const std::string& cache_dir, bool force) {
  std::vector<std::string> args = {
      "/proc/self/exe", "run",   (fs::path(run_dir) / "pipeline.yaml").string(),
      "--workdir",      run_dir, "--cache-dir",
      cache_dir};
  if (force) args.push_back("--force");
  ProcessOptions options;
  options.output_path = (fs::path(run_dir) / "run.log").string();
  options.append_output = false;
  return StartProcess(args, options);
}

// The checks a stage's "guardrails" verdict says fired: its "fired" list, or its true flags.
std::vector<std::string> FiredChecks(const json& verdict) {
  std::vector<std::string> fired;
  if (verdict.contains("fired") && verdict["fired"].is_array()) {
    return verdict["fired"].get<std::vector<std::string>>();
  }
  for (const auto& [name, value] : verdict.items()) {
    if (value.is_boolean() && value.get<bool>()) fired.push_back(name);
  }
  return fired;
}

// The sweep's tables (sweep.csv, sweep.json) and summary.json from the rows of its finished runs;
// `fields` are the summary's own keys (status, counts, times). Returns the summary.
json WriteSweepOutputs(const std::string& workdir, const std::vector<SweepRow>& table,
                       json fields) {
  WriteSweepTables(workdir, table);
  json rows_json = json::array();
  for (const SweepRow& row : table) rows_json.push_back(row.ToJson());
  fields["raytime_version"] = Version();
  fields["workdir"] = workdir;
  fields["runs"] = rows_json;
  WriteTextFileAtomically((fs::path(workdir) / "summary.json").string(), fields.dump(2));
  return fields;
}

}  // namespace

SweepRow SweepRowFromRun(const std::string& label,
                         const std::vector<std::pair<std::string, std::string>>& swept,
                         const std::string& run_dir) {
  SweepRow row;
  row.run = label;
  row.swept = swept;
  const fs::path summary_path = fs::path(run_dir) / "summary.json";
  const json summary = fs::exists(summary_path)
                           ? json::parse(ReadTextFile(summary_path.string()), nullptr, false)
                           : json();
  if (summary.is_discarded() || !summary.is_object()) {
    row.status = "failed";
    row.error = "no summary.json (see " + run_dir + "/run.log)";
    return row;
  }
  row.status = summary.value("status", "failed");
  // A process that ended without finishing its summary (killed) is a failure, not a result.
  if (row.status == "running") {
    row.status = "failed";
    row.error = "the run ended without finishing (see " + run_dir + "/run.log)";
  }
  if (summary.contains("error")) row.error = summary["error"].get<std::string>();
  row.seconds = summary.value("seconds", 0.0);
  // Copies: iterating items() of a temporary would outlive it.
  const json stages = summary.value("stages", json::array());
  const json metrics = summary.value("metrics", json::object());
  const json pose_sets = summary.value("pose_sets", json::object());
  const json guardrails = summary.value("guardrails", json::object());
  const json warnings = summary.value("warnings", json::array());
  std::set<std::string> splat_stages;  // their metrics are trainings per pose set, not pose errors
  for (const auto& stage : stages) {
    // Time of the stage's own computation, also when this run reused it.
    row.stage_seconds[stage["id"].get<std::string>()] = stage["status"] == "ran"
                                                            ? stage["seconds"].get<double>()
                                                            : stage.value("previous_seconds", 0.0);
    if (stage.value("type", "") == "splat") splat_stages.insert(stage["id"].get<std::string>());
  }
  for (const auto& [arm, by_alignment] : metrics.items()) {
    if (!by_alignment.is_object()) continue;
    if (splat_stages.count(arm)) {
      for (const auto& [pose_set, training] : by_alignment.items()) {
        if (training.is_object()) row.splat[arm][pose_set] = SweepSplatResult::FromJson(training);
      }
      continue;
    }
    for (const auto& [alignment, errors] : by_alignment.items()) {
      if (!errors.is_object()) continue;
      row.errors[arm][alignment] = errors.get<PoseErrorStatistics>();
    }
  }
  for (const auto& [pose_set, id] : pose_sets.items()) {
    row.pose_set_stage[pose_set] = id.get<std::string>();
  }
  for (const auto& [id, verdict] : guardrails.items()) {
    row.guardrails_fired[id] = FiredChecks(verdict);
  }
  for (const auto& warning : warnings) {
    row.warnings.push_back(warning.value("code", ""));
  }
  return row;
}

json CollectSweep(const std::string& workdir) {
  const std::string list_path = (fs::path(workdir) / "runs.json").string();
  if (!fs::exists(list_path)) {
    ThrowInput(list_path, 0,
               "no run list: not the work directory of a sweep (raytime run with a "
               "sweep section writes it)");
  }
  const json list = json::parse(ReadTextFile(list_path), nullptr, false);
  if (list.is_discarded() || !list.is_array()) ThrowInput(list_path, 0, "not a JSON array of runs");
  std::vector<SweepRow> rows;
  int failures = 0;
  double seconds = 0.0;
  for (const json& run : list) {
    if (!run.is_object() || !run.contains("label") || !run.contains("dir")) {
      ThrowInput(list_path, 0, "a run entry needs 'label', 'swept' and 'dir'");
    }
    rows.push_back(SweepRowFromRun(
        run["label"].get<std::string>(),
        run.value("swept", json::array()).get<std::vector<std::pair<std::string, std::string>>>(),
        run["dir"].get<std::string>()));
    if (!rows.back().Succeeded()) ++failures;
    seconds += rows.back().seconds;
  }
  const json summary = WriteSweepOutputs(workdir, rows,
                                         {{"num_runs", rows.size()},
                                          {"failures", failures},
                                          {"status", failures ? "failed" : "ok"},
                                          {"collected", true},
                                          {"run_seconds", seconds}});
  spdlog::info(fmt::format("sweep: collected {} runs ({} failed) into {}/sweep.csv", rows.size(),
                           failures, workdir));
  return summary;
}

void ThrowIfRunsFailed(int failures, size_t num_runs, const std::string& workdir) {
  if (failures == 0) return;
  throw InputError(std::to_string(failures) + " of " + std::to_string(num_runs) +
                   " sweep runs failed (see " + workdir + "/sweep.csv and each run.log)");
}

namespace {

// Each run's folder with its pipeline.yaml, and WORKDIR/runs.json listing them; returns the
// folders, in the runs' order.
std::vector<std::string> PrepareRuns(const std::vector<SweepRun>& runs,
                                     const std::string& workdir) {
  std::vector<std::string> run_dirs;
  for (const SweepRun& run : runs) {
    run_dirs.push_back((fs::path(workdir) / "runs" / run.label).string());
    fs::create_directories(run_dirs.back());
    WriteTextFileAtomically((fs::path(run_dirs.back()) / "pipeline.yaml").string(),
                            PipelineToYaml(run.spec));
  }
  json run_list = json::array();
  for (size_t i = 0; i < runs.size(); ++i) {
    run_list.push_back({{"label", runs[i].label}, {"swept", runs[i].swept}, {"dir", run_dirs[i]}});
  }
  WriteTextFileAtomically((fs::path(workdir) / "runs.json").string(), run_list.dump(2));
  return run_dirs;
}

// The local backend: the runs as child processes, `jobs` at a time; a row per finished run and
// the tables rewritten after each. On SIGINT/SIGTERM the running children are stopped, every row
// finished so far kept, and the sweep said to be interrupted.
class LocalSweep {
 public:
  LocalSweep(const PipelineSpec& spec, const std::string& workdir,
             const std::vector<SweepRun>& runs, const std::vector<std::string>& run_dirs,
             const std::string& cache_dir, bool force, int jobs)
      : spec_(spec),
        workdir_(workdir),
        runs_(runs),
        run_dirs_(run_dirs),
        cache_dir_(cache_dir),
        force_(force),
        jobs_(jobs),
        rows_(runs.size()),
        finished_(runs.size(), false) {}

  void Run() {
    const InterruptAction on_interrupt([&](int signal) {
      std::lock_guard<std::mutex> lock(mutex_);
      StopRunning();
      Write("interrupted");
      spdlog::error(fmt::format(
          "sweep interrupted (signal {}): {} of {} runs have rows in {}/sweep.csv", signal,
          std::count(finished_.begin(), finished_.end(), true), runs_.size(), workdir_));
    });
    size_t done = 0;
    while (done < runs_.size()) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        StartRuns();
      }
      const pid_t pid = WaitAnyProcess().pid;
      std::lock_guard<std::mutex> lock(mutex_);
      const auto it = running_.find(pid);
      if (it == running_.end()) continue;
      const size_t index = it->second;
      running_.erase(it);
      ++done;
      Finish(index, done);
      Write(done < runs_.size() ? "running" : (failures_ ? "failed" : "ok"));
    }
    ThrowIfRunsFailed(failures_, runs_.size(), workdir_);
  }

 private:
  // Starts runs until `jobs` are under way (the caller holds mutex_). A run that cannot start
  // stops the sweep: the runs not started are not rows, the summary says it failed and why, never
  // "running" with nothing left running; runs under way are stopped and keep their rows.
  void StartRuns() {
    while (next_ < runs_.size() && static_cast<int>(running_.size()) < jobs_) {
      try {
        running_[SpawnRun(run_dirs_[next_], cache_dir_, force_)] = next_;
      } catch (const std::exception& e) {
        StopRunning();
        const std::string error = std::string("run ") + runs_[next_].label + ": " + e.what();
        Write("failed", error);
        throw std::runtime_error("sweep stopped: " + error);
      }
      ++next_;
    }
  }

  // The row of the finished run `index`, the `done`-th, with its line in the log.
  void Finish(size_t index, size_t done) {
    rows_[index] = SweepRowFromRun(runs_[index].label, runs_[index].swept, run_dirs_[index]);
    finished_[index] = true;
    const SweepRow& row = rows_[index];
    if (!row.Succeeded()) ++failures_;
    spdlog::info(fmt::format("sweep: {}/{} {} {} ({:.1f} s)", done, runs_.size(), row.run,
                             row.status, row.seconds));
    if (!row.Succeeded()) {
      spdlog::error(fmt::format("sweep run {} failed: {}", row.run,
                                row.error.empty() ? std::string("see run.log") : row.error));
    }
  }

  // Stops the running children (each writes its own "interrupted" summary) and keeps their rows;
  // the caller holds mutex_.
  void StopRunning() {
    for (const auto& [pid, index] : running_) SignalProcess(pid, SIGTERM);
    for (const auto& [pid, index] : running_) {
      WaitProcess(pid);
      rows_[index] = SweepRowFromRun(runs_[index].label, runs_[index].swept, run_dirs_[index]);
      finished_[index] = true;
    }
    running_.clear();
  }

  void Write(const std::string& status, const std::string& error = "") {
    std::vector<SweepRow> table;
    for (size_t i = 0; i < runs_.size(); ++i) {
      if (finished_[i]) table.push_back(rows_[i]);
    }
    json fields = {{"pipeline", spec_.path},   {"name", spec_.name},
                   {"num_runs", runs_.size()}, {"failures", failures_},
                   {"status", status},         {"seconds", SecondsSince(start_)}};
    if (!error.empty()) fields["error"] = error;
    WriteSweepOutputs(workdir_, table, fields);
  }

  const PipelineSpec& spec_;
  const std::string& workdir_;
  const std::vector<SweepRun>& runs_;
  const std::vector<std::string>& run_dirs_;
  const std::string& cache_dir_;
  const bool force_;
  const int jobs_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::mutex mutex_;  // rows and running children, shared with the interrupt watcher
  std::vector<SweepRow> rows_;
  std::vector<bool> finished_;
  std::map<pid_t, size_t> running_;
  size_t next_ = 0;
  int failures_ = 0;
};

}  // namespace

json RunSweep(const PipelineSpec& spec, const std::string& workdir, const RunOptions& options) {
  const std::vector<SweepRun> runs = ExpandSweep(spec);
  const int jobs = options.jobs > 0
                       ? options.jobs
                       : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const std::string cache_dir =
      options.cache_dir.empty() ? (fs::path(workdir) / "cache").string() : options.cache_dir;
  fs::create_directories(workdir);
  RemoveStaleTemporaryFiles(workdir);
  spdlog::info(fmt::format("sweep: {} runs, {} at a time, cache {}", runs.size(), jobs, cache_dir));
  const std::vector<std::string> run_dirs = PrepareRuns(runs, workdir);
  if (options.backend == "slurm") {
    return SubmitSweepToSlurm(spec, workdir, runs, run_dirs, cache_dir, options);
  }
  if (options.backend != "local") {
    throw InputError("sweep: unknown backend '" + options.backend + "' (local or slurm)");
  }
  LocalSweep(spec, workdir, runs, run_dirs, cache_dir, options.force, jobs).Run();
  return json::parse(ReadTextFile((fs::path(workdir) / "summary.json").string()));
}

}  // namespace raytime
