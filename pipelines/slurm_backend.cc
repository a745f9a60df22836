#include "pipelines/slurm_backend.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <sstream>
#include <thread>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/process.h"
#include "pipelines/sweep.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// What identifies a run's scene: its swept dataset.* values (runs of one scene share the
// features and matches stages through the cache).
std::string SceneKey(const SweepRun& run) {
  std::string key;
  for (const auto& [name, value] : run.swept) {
    if (name.rfind("dataset.", 0) == 0) key += name + "=" + value + ";";
  }
  return key;
}

// Runs `argv` with its output (stdout and stderr) to `output_path`, which it also returns in *text.
ProcessStatus RunWithOutput(const std::vector<std::string>& argv, const std::string& output_path,
                            std::string* text) {
  ProcessOptions process;
  process.output_path = output_path;
  process.append_output = false;
  const ProcessStatus status = RunProcess(argv, process);
  *text = fs::exists(output_path) ? ReadTextFile(output_path) : std::string();
  return status;
}

// Runs sbatch with `args` and returns the job id it prints (--parsable: "ID" or "ID;cluster").
std::string Submit(const std::vector<std::string>& args, const std::string& slurm_dir,
                   const std::string& what) {
  std::vector<std::string> argv = {"sbatch", "--parsable"};
  argv.insert(argv.end(), args.begin(), args.end());
  std::string text;
  const ProcessStatus status =
      RunWithOutput(argv, (fs::path(slurm_dir) / ("sbatch_" + what + ".out")).string(), &text);
  if (!status.Succeeded()) {
    throw InputError("sweep: sbatch " + status.Describe() + " submitting the " + what + ": " +
                     text + " (command: " + CommandLine(argv) +
                     "; is Slurm installed and a cluster running? scripts/slurm_local.sh start "
                     "makes a one-node one)");
  }
  std::istringstream lines(text);
  std::string id;
  std::string line;
  while (std::getline(lines, line)) {
    if (!line.empty() && std::isdigit(static_cast<unsigned char>(line[0]))) id = line;
  }
  if (id.empty()) throw InputError("sweep: sbatch printed no job id for the " + what + ": " + text);
  return id.substr(0, id.find(';'));
}

// Waits until job `id` has left Slurm's queue or reached a final state. Not `sbatch --wait`: its
// poll interval grows to 32 s, which made every waited sweep end up to half a minute after its
// last job (the Slurm test spent 56 of its 59 s waiting). Here the interval grows from 1 s by half
// each poll to 10 s: one squeue call every 10 s on a long campaign.
void WaitForJob(const std::string& id, const std::string& slurm_dir) {
  const std::string output = (fs::path(slurm_dir) / "squeue_wait.out").string();
  double interval_s = 1.0;
  int failures = 0;
  while (true) {
    std::this_thread::sleep_for(std::chrono::duration<double>(interval_s));
    interval_s = std::min(1.5 * interval_s, 10.0);
    std::string text;
    const ProcessStatus status =
        RunWithOutput({"squeue", "--noheader", "--jobs=" + id, "--format=%T"}, output, &text);
    if (!status.Succeeded()) {
      // A job purged from the controller's memory (MinJobAge after it ended) is unknown.
      if (text.find("Invalid job id") != std::string::npos) return;
      if (++failures == 30) {
        throw InputError("sweep: squeue " + status.Describe() + " 30 times waiting for job " + id +
                         ": " + text);
      }
      continue;
    }
    failures = 0;
    // Empty: the job has left the queue. Otherwise its state; every state but these is final.
    bool waiting = false;
    std::istringstream lines(text);
    std::string state;
    while (lines >> state) {
      waiting = waiting || state == "PENDING" || state == "RUNNING" || state == "CONFIGURING" ||
                state == "COMPLETING" || state == "SUSPENDED" || state == "REQUEUED" ||
                state == "RESIZING" || state == "SIGNALING" || state == "STAGE_OUT";
    }
    if (!waiting) return;
  }
}

void WriteLines(const std::string& path, const std::vector<std::string>& lines) {
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  WriteTextFileAtomically(path, text);
}

}  // namespace

json SubmitSweepToSlurm(const PipelineSpec& spec, const std::string& workdir,
                        const std::vector<SweepRun>& runs, const std::vector<std::string>& run_dirs,
                        const std::string& cache_dir, const RunOptions& options) {
  const std::string slurm_dir = (fs::path(workdir) / "slurm").string();
  fs::create_directories(slurm_dir);
  const std::string exe = fs::read_symlink("/proc/self/exe").string();

  // Runs to submit: every run without a successful summary (all with --force).
  std::vector<std::string> leaders, followers;
  std::map<std::string, bool> scene_led;
  int skipped = 0;
  for (size_t i = 0; i < runs.size(); ++i) {
    if (!options.force && SweepRowFromRun(runs[i].label, runs[i].swept, run_dirs[i]).Succeeded()) {
      ++skipped;
      continue;
    }
    const std::string dir = fs::absolute(run_dirs[i]).string();
    const std::string scene = SceneKey(runs[i]);
    if (scene_led.count(scene) == 0) {
      scene_led[scene] = true;
      leaders.push_back(dir);
    } else {
      followers.push_back(dir);
    }
  }

  // One array task = one run, from the list file given as the script's argument.
  const std::string task_script = (fs::path(slurm_dir) / "run_task.sh").string();
  std::string script =
      "#!/bin/bash\n"
      "# One sweep run per Slurm array task (raytime's Slurm backend, pipelines/slurm_backend.h).\n"
      "set -euo pipefail\n"
      "run=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" \"$1\")\n"
      "exec " +
      CommandLine({exe, "run"}) + " \"$run/pipeline.yaml\" --workdir \"$run\" " +
      CommandLine({"--cache-dir", fs::absolute(cache_dir).string()}) +
      (options.force ? " --force" : "") + " > \"$run/run.log\" 2>&1\n";
  WriteTextFileAtomically(task_script, script);
  fs::permissions(task_script, fs::perms::owner_all, fs::perm_options::add);

  std::vector<std::string> common = {"--output", (fs::path(slurm_dir) / "%x-%A_%a.out").string()};
  if (!options.partition.empty()) common.push_back("--partition=" + options.partition);
  const std::string name = spec.name.empty() ? std::string("sweep") : spec.name;
  json jobs = json::object();
  std::vector<std::string> after;
  std::string leader_job;
  if (!leaders.empty()) {
    const std::string list = (fs::path(slurm_dir) / "leaders.txt").string();
    WriteLines(list, leaders);
    std::vector<std::string> args = common;
    args.insert(args.end(), {"--job-name=raytime-" + name + "-leaders",
                             "--array=0-" + std::to_string(leaders.size() - 1), task_script, list});
    leader_job = Submit(args, slurm_dir, "leaders");
    jobs["leaders"] = {{"id", leader_job}, {"runs", leaders.size()}};
    after.push_back(leader_job);
  }
  if (!followers.empty()) {
    const std::string list = (fs::path(slurm_dir) / "followers.txt").string();
    WriteLines(list, followers);
    std::vector<std::string> args = common;
    if (!leader_job.empty()) args.push_back("--dependency=afterany:" + leader_job);
    args.insert(args.end(),
                {"--job-name=raytime-" + name + "-followers",
                 "--array=0-" + std::to_string(followers.size() - 1), task_script, list});
    const std::string id = Submit(args, slurm_dir, "followers");
    jobs["followers"] = {{"id", id}, {"runs", followers.size()}};
    after.push_back(id);
  }
  // The rows, tables and report once every run has ended.
  std::vector<std::string> args = {"--output", (fs::path(slurm_dir) / "%x-%j.out").string(),
                                   "--job-name=raytime-" + name + "-collect"};
  if (!options.partition.empty()) args.push_back("--partition=" + options.partition);
  if (!after.empty()) {
    std::string dependency = "--dependency=afterany";
    for (const std::string& id : after) dependency += ":" + id;
    args.push_back(dependency);
  }
  args.push_back("--wrap=" + CommandLine({exe, "report", "--sweep", fs::absolute(workdir).string(),
                                          "--collect"}));
  spdlog::info(fmt::format(
      "sweep: submitting {} runs to Slurm ({} scene leaders, {} followers; {} done already), "
      "scripts and Slurm output in {}",
      leaders.size() + followers.size(), leaders.size(), followers.size(), skipped, slurm_dir));
  const std::string collect_job = Submit(args, slurm_dir, "collect");
  jobs["collect"] = {{"id", collect_job}};
  const json submission = {{"backend", "slurm"},
                           {"jobs", jobs},
                           {"submitted", leaders.size() + followers.size()},
                           {"skipped", skipped}};
  WriteTextFileAtomically((fs::path(slurm_dir) / "jobs.json").string(), submission.dump(2));
  spdlog::info(
      fmt::format("sweep: Slurm jobs {} (then `raytime report --sweep {}`)", jobs.dump(), workdir));
  if (!options.slurm_wait) return submission;
  spdlog::info(fmt::format("sweep: waiting for the collect job {}", collect_job));
  WaitForJob(collect_job, slurm_dir);
  const json summary = CollectSweep(workdir);
  ThrowIfRunsFailed(summary.value("failures", 0), runs.size(), workdir);
  return summary;
}

}  // namespace raytime
