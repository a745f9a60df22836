#include "pipelines/stage_cache.h"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <map>
#include <mutex>

#include "core/atomic_file.h"
#include "core/content_hash.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/interrupt.h"
#include "core/resource_failure.h"
#include "core/timing.h"
#include "core/version.h"
#include "core/warnings.h"
#include "core/written_files.h"
#include "pipelines/stage.h"
#include "report/run_report.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  char buffer[32];
  std::strftime(buffer, sizeof(buffer), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return buffer;
}

// Artifacts found in a stage's HDF5 output.
std::vector<std::string> ArtifactsIn(const std::string& path) {
  const Hdf5Reader reader(path);
  std::vector<std::string> artifacts;
  if (reader.HasImages()) artifacts.push_back(kArtifactImages);
  for (const auto& name : reader.PoseSetNames()) artifacts.push_back(PoseArtifact(name));
  if (reader.HasFeatures()) artifacts.push_back("features");
  if (reader.HasMatches()) artifacts.push_back("matches");
  if (reader.HasJson(kArtifactNerfstudioTransforms)) {
    artifacts.push_back(kArtifactNerfstudioTransforms);
  }
  return artifacts;
}

struct ArtifactSource {
  std::string file;
  std::string stage_key;  // content key of the stage that wrote it
};

// Exclusive lock on a cache key, held while one process computes or copies that stage, so
// parallel sweep runs needing the same stage compute it once.
class CacheLock {
 public:
  CacheLock(const std::string& cache_dir, const std::string& key) {
    fs::create_directories(cache_dir);
    fd_ = ::open((fs::path(cache_dir) / (key + ".lock")).c_str(), O_CREAT | O_RDWR, 0644);
    if (fd_ >= 0) ::flock(fd_, LOCK_EX);
  }
  ~CacheLock() {
    if (fd_ >= 0) ::close(fd_);  // releases the lock
  }
  CacheLock(const CacheLock&) = delete;
  CacheLock& operator=(const CacheLock&) = delete;

 private:
  int fd_ = -1;
};

// Hard link where possible (the cache and the runs share a file system), copy otherwise; the
// target appears atomically. Writers never modify an HDF5 file in place (they rename a new one
// over it), so linked copies cannot change under a reader.
void LinkOrCopy(const fs::path& from, const fs::path& to) {
  WriteAtomically(to.string(), [&](const std::string& tmp) {
    std::error_code error;
    fs::create_hard_link(from, tmp, error);
    if (error) fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
  });
}

// What a stage's content key is made of. The id is in it ("refine@gnc" writes pose set
// "refined@gnc", not "refined"), and so is the executable's contents, so a rebuilt raytime never
// reuses a stage output computed by different code (the version string alone does not change
// between development builds).
std::string StageKey(const PipelineStageSpec& stage_spec, Stage& stage,
                     const std::map<std::string, ArtifactSource>& artifacts) {
  json material = {{"id", stage_spec.id},
                   {"version", Version()},
                   {"executable", ExecutableHash()},
                   {"options", stage.OptionsJson()},
                   {"inputs", json::object()},
                   {"external", json::object()}};
  for (const auto& input : stage.Inputs()) {
    const auto it = artifacts.find(input);
    material["inputs"][input] = it == artifacts.end() ? "" : it->second.stage_key;
  }
  for (const auto& file : stage.ExternalFiles()) {
    material["external"][file] = HashFileContents(file);
  }
  return HashBytes(material.dump());
}

// summary.json of one run: rewritten (atomically) at every change, also from the interrupt
// watcher's thread, hence the lock.
class RunSummary {
 public:
  RunSummary(const std::string& path, json summary) : path_(path), summary_(std::move(summary)) {}

  // When the run started, on the file system's clock, less the lag of the coarse clock file
  // times are taken from: what changed since was written by this run.
  const fs::file_time_type started =
      fs::file_time_type::clock::now() - std::chrono::milliseconds(20);

  template <typename Change>
  void Update(Change&& change) {
    std::lock_guard<std::mutex> lock(mutex_);
    change(summary_);
    WriteTextFileAtomically(path_, summary_.dump(2));
  }
  json Get() {
    std::lock_guard<std::mutex> lock(mutex_);
    return summary_;
  }

 private:
  std::string path_;
  std::mutex mutex_;
  json summary_;
};

// The checks a stage reports as fired, for the run's guardrails section.
void CollectStage(const std::string& id, const json& stage_summary, json* summary) {
  if (stage_summary.contains("metrics")) (*summary)["metrics"].update(stage_summary["metrics"]);
  if (stage_summary.contains("agreement")) {
    for (const auto& [reference, scores] : stage_summary["agreement"].items()) {
      (*summary)["agreement"][reference].update(scores);
    }
  }
  if (stage_summary.contains("guardrails")) {
    (*summary)["guardrails"][id] = stage_summary["guardrails"];
  }
  if (stage_summary.contains("warnings")) {
    for (json warning : stage_summary["warnings"]) {
      warning["stage"] = id;
      (*summary)["warnings"].push_back(warning);
    }
  }
}

// Whether a stage entry of summary.json says the stage's result is this run's.
bool Completed(const json& entry) {
  const std::string status = entry.value("status", "");
  return status == "ran" || status == "skipped" || status == "cached";
}

// Clears WORKDIR/stale/`output` for a new move: removed when raytime wrote all of it, else (files
// of the user's in it, or an earlier raytime's folder without a record) kept under a dated name.
void ClearStaleSlot(const fs::path& to) {
  std::error_code error;
  if (!fs::exists(fs::symlink_status(to, error))) return;
  if (fs::is_directory(to, error) && !FilesNotWritten(to.string()).empty()) {
    fs::rename(to, DatedUnusedPath(to.string()), error);
    if (!error) return;
  }
  fs::remove_all(to, error);
}

// Whether `path` (a file, or a folder's newest entry) changed at or after `since`.
bool ChangedSince(const fs::path& path, fs::file_time_type since) {
  std::error_code error;
  if (fs::last_write_time(path, error) >= since && !error) return true;
  if (!fs::is_directory(path, error)) return false;
  for (fs::recursive_directory_iterator it(path, error), end; !error && it != end;
       it.increment(error)) {
    std::error_code entry_error;
    if (fs::last_write_time(it->path(), entry_error) >= since && !entry_error) return true;
  }
  return false;
}

// Moves WORKDIR/`output` (a file or folder a run wrote: an earlier one, or this one's stage
// before it failed) to WORKDIR/stale/`output`; false when there is nothing to move or it cannot
// be moved (said in the log). Of a folder raytime recorded writing, only its files move: the
// user's stay where they are (core/written_files.h). `run_start`: when this run started, for the
// log's word on whose output it was.
bool MoveAside(const std::string& workdir, const std::string& output, const std::string& why,
               fs::file_time_type run_start) {
  const fs::path from = fs::path(workdir) / output;
  std::error_code error;
  if (!fs::exists(fs::symlink_status(from, error))) return false;
  const bool recorded = fs::exists(from / kWrittenFilesRecord, error);
  const std::vector<std::string> theirs =
      recorded ? FilesNotWritten(from.string()) : std::vector<std::string>();
  const std::string whose = ChangedSince(from, run_start) ? "this run wrote it before it stopped"
                                                          : "it is from before this run";
  const fs::path to = fs::path(workdir) / "stale" / output;
  ClearStaleSlot(to);
  fs::create_directories(to.parent_path(), error);
  fs::rename(from, to, error);
  if (error) {
    spdlog::error(fmt::format("cannot move {} aside ({}): it is not this run's result",
                              from.string(), error.message()));
    return false;
  }
  spdlog::warn(fmt::format("moved {} to {}: {}, and {}", from.string(), to.string(), whose, why));
  if (!theirs.empty()) {
    fs::create_directories(from, error);
    CarryEntriesOver(theirs, to.string(), from.string());
    spdlog::warn(fmt::format("kept {} file(s) raytime did not write in {} (first: {})",
                             theirs.size(), from.string(), theirs.front()));
  }
  return true;
}

// Files and folders that stages which did not complete in this run had written in an earlier one
// (an export's refined/ and refined_transforms.json): moved to WORKDIR/stale/ when the run fails
// or is interrupted, so that a failed run never leaves poses of other inputs or options under the
// names users train from. Returns the paths moved, relative to the work directory.
std::vector<std::string> MoveStaleOutputs(const PipelineSpec& spec, const std::string& workdir,
                                          const json& stages, fs::file_time_type run_start) {
  std::vector<std::string> moved;
  for (const PipelineStageSpec& stage_spec : spec.stages) {
    const bool done = std::any_of(stages.begin(), stages.end(), [&](const json& entry) {
      return entry.value("id", "") == stage_spec.id && Completed(entry);
    });
    if (done) continue;
    // A stage that does not configure wrote nothing under this configuration.
    const std::unique_ptr<Stage> stage =
        ConfiguredStageOrNull(stage_spec.type, stage_spec.options, spec.path);
    if (!stage) continue;
    for (const std::string& output : stage->ExtraOutputs()) {
      if (MoveAside(workdir, output, "this run did not complete its stage " + stage_spec.id,
                    run_start)) {
        moved.push_back(output);
      }
    }
  }
  return moved;
}

// The outputs besides its HDF5 file that a stage's earlier run recorded and this run's options no
// longer write (an export format or pose set dropped): moved aside, so that the work directory
// does not mix this run's exports with an earlier run's.
std::vector<std::string> MoveOutputsNoLongerWritten(const std::string& workdir,
                                                    const std::string& stage_id,
                                                    const json& previous_record,
                                                    const std::vector<std::string>& outputs,
                                                    fs::file_time_type run_start) {
  std::vector<std::string> moved;
  if (!previous_record.is_object() || !previous_record.contains("extra_outputs")) return moved;
  for (const json& previous : previous_record["extra_outputs"]) {
    if (!previous.is_string()) continue;
    const std::string output = previous.get<std::string>();
    if (std::find(outputs.begin(), outputs.end(), output) != outputs.end()) continue;
    if (MoveAside(workdir, output, "stage " + stage_id + " no longer writes it", run_start)) {
      moved.push_back(output);
    }
  }
  return moved;
}

// summary.json's stale_outputs_moved lists every output this run moved aside, however it came to
// (a failed or interrupted run's summary always has the list).
void AppendStaleOutputs(const std::vector<std::string>& moved, json* summary) {
  json& list = (*summary)["stale_outputs_moved"];
  if (!list.is_array()) list = json::array();
  for (const std::string& output : moved) list.push_back(output);
}

}  // namespace

void LogWarnings(const std::string& stage_id, const json& stage_summary) {
  if (!stage_summary.contains("warnings")) return;
  for (const json& warning : stage_summary["warnings"]) {
    spdlog::warn(fmt::format("{}: {} [{}]", stage_id, warning.value("message", ""),
                             warning.value("code", "")));
  }
}

namespace {

// The stage of a pipeline file's entry, configured; an option error names the file and line.
std::unique_ptr<Stage> ConfiguredStage(const PipelineSpec& spec,
                                       const PipelineStageSpec& stage_spec) {
  std::unique_ptr<Stage> stage = CreateStage(stage_spec.type);
  try {
    stage->Configure(stage_spec.options, spec.path);
  } catch (const InputError& e) {
    const std::string message = e.what();
    if (message.rfind(spec.path + ":", 0) == 0) throw;
    ThrowInput(spec.path, stage_spec.line, message);
  }
  return stage;
}

// 1. Whether this work directory already holds the stage's result for `key` (complete, undamaged,
// readable); `produced` receives its artifacts.
bool PreviousResultHolds(Stage& stage, const StageContext& context, const json& previous_record,
                         const std::string& key, const std::string& record_path,
                         const std::string& tag, bool force, std::vector<std::string>* produced) {
  if (force || !fs::exists(record_path) || !fs::exists(context.output_path)) return false;
  if (previous_record.is_discarded() || previous_record.value("key", "") != key) return false;
  for (const auto& extra : stage.ExtraOutputs()) {
    if (!fs::exists(fs::path(context.workdir) / extra)) return false;
  }
  if (!stage.Complete(context)) {
    spdlog::info(fmt::format("{}: the previous result is incomplete, running again", tag));
    return false;
  }
  // A file damaged since it was written (same size, other bytes) is not reused.
  if (previous_record.contains("output_hash") &&
      previous_record["output_hash"] != HashFileContents(context.output_path)) {
    spdlog::warn(fmt::format(
        "{}: {} is not the file this stage wrote (its content checksum differs: damaged or "
        "changed since), running the stage again",
        tag, context.output_path));
    return false;
  }
  try {
    *produced = ArtifactsIn(context.output_path);
  } catch (const InputError& e) {
    spdlog::warn(fmt::format("{}: previous output is unreadable, rerunning ({})", tag, e.what()));
    return false;
  }
  return true;
}

// The stage's output of its previous run here, for item-by-item reuse (StageContext::
// previous_output): only the file that run recorded writing (same checksum), never with --force.
std::string VerifiedPreviousOutput(const StageContext& context, const json& previous_record,
                                   bool force) {
  if (force || previous_record.is_discarded() || !previous_record.contains("output_hash") ||
      !fs::exists(context.output_path)) {
    return "";
  }
  if (previous_record["output_hash"] != HashFileContents(context.output_path)) return "";
  return context.output_path;
}

// 2. The record of a result another run left in the shared cache under `key`; null when there is
// none, it is damaged (no record or checksum, or the content differs) or it is another key's (an
// entry moved or copied under a folder name it was not computed for).
json CachedRecord(const fs::path& cached, const std::string& key, const std::string& tag) {
  if (!fs::exists(cached / "record.json")) return json();
  const json record = json::parse(ReadTextFile((cached / "record.json").string()), nullptr, false);
  if (record.is_discarded() || !record.contains("output_hash") ||
      !fs::exists(cached / "output.h5") ||
      record["output_hash"] != HashFileContents((cached / "output.h5").string())) {
    spdlog::warn(
        fmt::format("{}: the cached result in {} is damaged (no record or checksum, or the content "
                    "differs), computing it again",
                    tag, cached.string()));
    return json();
  }
  if (record.value("key", "") != key) {
    spdlog::warn(fmt::format(
        "{}: the cached result in {} was computed for another key ({}): moved or copied there, "
        "not this stage's; computing it again",
        tag, cached.string(), record.value("key", "none")));
    return json();
  }
  return record;
}

// 3. Runs the stage and returns its record; null when a stage that does not stop the run failed
// (said in `entry`, summary.json's warnings and the log: the run goes on, and the stage runs again
// next time, having no record).
json RunStageNow(Stage& stage, const PipelineStageSpec& stage_spec, const StageContext& context,
                 const std::string& key, const json& previous_record, const std::string& tag,
                 RunSummary* run, json* entry) {
  spdlog::info(fmt::format("{}: {}", tag, stage.description()));
  const auto start = std::chrono::steady_clock::now();
  json stage_summary;
  try {
    stage_summary = stage.Run(context);
  } catch (const MissingArtifactError&) {
    throw;  // the pipeline needs fixing, whatever stage this is
  } catch (const std::exception& e) {
    if (stage.FailureStopsRun() || Interrupting()) throw;
    // A measurement that could not be made (a Sim(3) of two cameras).
    const std::string message = fmt::format(
        "{} failed: {}; the stages after it went on (stage type {} does not stop the run)",
        stage_spec.id, e.what(), stage_spec.type);
    spdlog::error(fmt::format("{}: {}", tag, message));
    (*entry)["status"] = "failed";
    (*entry)["error"] = e.what();
    (*entry)["seconds"] = SecondsSince(start);
    run->Update([&](json& summary) {
      summary["stages"].push_back(*entry);
      json warning = Warning{"stage_failed", message, {}, {}, {{"error", e.what()}}}.ToJson();
      warning["stage"] = stage_spec.id;
      summary["warnings"].push_back(warning);
    });
    return json();
  }
  const double seconds = SecondsSince(start);
  spdlog::info(fmt::format("{}: done in {:.2f} s", tag, seconds));
  const json record = {{"key", key},
                       {"summary", stage_summary},
                       {"seconds", seconds},
                       {"finished_utc", UtcNow()},
                       {"output_hash", HashFileContents(context.output_path)},
                       {"extra_outputs", stage.ExtraOutputs()}};
  const std::vector<std::string> moved = MoveOutputsNoLongerWritten(
      context.workdir, stage_spec.id, previous_record, stage.ExtraOutputs(), run->started);
  if (!moved.empty()) run->Update([&](json& summary) { AppendStaleOutputs(moved, &summary); });
  (*entry)["status"] = "ran";
  (*entry)["seconds"] = seconds;
  return record;
}

// One stage of the run: reused from the work directory, taken from the shared cache, or run.
void StepStage(const PipelineSpec& spec, size_t index, const std::string& workdir,
               const RunOptions& options, RunSummary* run,
               std::map<std::string, ArtifactSource>* artifacts) {
  const PipelineStageSpec& stage_spec = spec.stages[index];
  run->Update([&](json& summary) { summary["stage"] = stage_spec.id; });
  const std::unique_ptr<Stage> stage = ConfiguredStage(spec, stage_spec);
  const std::string tag = "[" + std::to_string(index + 1) + "/" +
                          std::to_string(spec.stages.size()) + "] " + stage_spec.id;
  StageContext context;
  context.stage_id = stage_spec.id;
  context.workdir = workdir;
  context.output_path = (fs::path(workdir) / (stage_spec.id + ".h5")).string();
  context.force = options.force;
  for (const auto& [artifact, source] : *artifacts) context.artifacts[artifact] = source.file;
  const std::string key = StageKey(stage_spec, *stage, *artifacts);
  const std::string record_path =
      (fs::path(workdir) / ".raytime" / (stage_spec.id + ".json")).string();
  // What the stage's earlier run in this work directory recorded (none: {}).
  const json previous_record = fs::exists(record_path)
                                   ? json::parse(ReadTextFile(record_path), nullptr, false)
                                   : json::object();

  json entry = {{"id", stage_spec.id},
                {"type", stage_spec.type},
                {"key", key},
                {"options", stage->OptionsJson()}};
  json record;
  std::vector<std::string> produced;
  if (PreviousResultHolds(*stage, context, previous_record, key, record_path, tag, options.force,
                          &produced)) {
    spdlog::info(fmt::format("{}: inputs and options unchanged, skipped", tag));
    record = previous_record;
    entry["status"] = "skipped";
    entry["seconds"] = 0.0;
    entry["previous_seconds"] = record["seconds"];
  } else {
    // Sweeps share a cache; stages that write folders besides their HDF5 file always run. The
    // lock makes a second run wait for the first's result instead of computing it again.
    const bool cacheable = !options.cache_dir.empty() && stage->Cacheable();
    std::unique_ptr<CacheLock> lock;
    const fs::path cached = fs::path(options.cache_dir) / key;
    if (cacheable) lock = std::make_unique<CacheLock>(options.cache_dir, key);
    const json cached_record =
        cacheable && !options.force ? CachedRecord(cached, key, tag) : json();
    if (!cached_record.is_null()) {
      spdlog::info(fmt::format("{}: computed by another run, taken from the cache", tag));
      record = cached_record;
      LinkOrCopy(cached / "output.h5", context.output_path);
      entry["status"] = "cached";
      entry["seconds"] = 0.0;
      entry["previous_seconds"] = record["seconds"];
    } else {
      context.previous_output = VerifiedPreviousOutput(context, previous_record, options.force);
      record = RunStageNow(*stage, stage_spec, context, key, previous_record, tag, run, &entry);
      if (record.is_null()) return;  // failed without stopping the run, recorded
      if (cacheable) {
        WriteDirectoryAtomically(cached.string(), [&](const std::string& dir) {
          LinkOrCopy(context.output_path, fs::path(dir) / "output.h5");
          WriteTextFileAtomically((fs::path(dir) / "record.json").string(), record.dump(2));
        });
      }
    }
    WriteTextFileAtomically(record_path, record.dump(2));
    produced = ArtifactsIn(context.output_path);
  }
  entry["summary"] = record["summary"];
  LogWarnings(stage_spec.id, entry["summary"]);
  for (const auto& artifact : produced) (*artifacts)[artifact] = {context.output_path, key};
  run->Update([&](json& summary) {
    for (const auto& artifact : produced) {
      // Which stage wrote each pose set, for reports that time an arm by its stage.
      if (artifact.rfind("poses/", 0) == 0) {
        summary["pose_sets"][artifact.substr(6)] = stage_spec.id;
      }
    }
    CollectStage(stage_spec.id, entry["summary"], &summary);
    summary["stages"].push_back(entry);
  });
}

// Once the images are known, the stages after `first` refuse names they could not write, before
// any of them works (Stage::CheckImageNames).
void CheckImageNamesAhead(const PipelineSpec& spec, size_t first, const std::string& images_file) {
  std::vector<std::string> names;
  for (const ImageInfo& image : Hdf5Reader(images_file).ReadImages().images) {
    names.push_back(image.name);
  }
  for (size_t j = first; j < spec.stages.size(); ++j) {
    ConfiguredStage(spec, spec.stages[j])->CheckImageNames(names);
  }
}

// WORKDIR/report.html (run_report.h); a page that cannot be written is said in the log, never
// the run's failure.
void WriteReportPage(const std::string& workdir) {
  try {
    spdlog::info(fmt::format("report: {}", WriteRunReport(workdir)));
  } catch (const std::exception& e) {
    spdlog::warn(fmt::format("report: cannot write {}/report.html: {}", workdir, e.what()));
  }
}

}  // namespace

json RunStages(const PipelineSpec& spec, const std::string& workdir, const RunOptions& options) {
  const auto run_start = std::chrono::steady_clock::now();
  fs::create_directories(fs::path(workdir) / ".raytime");
  for (const auto& path : RemoveStaleTemporaryFiles(workdir)) {
    spdlog::info(fmt::format("removed {} (left by an interrupted run)", path));
  }
  if (!options.cache_dir.empty()) RemoveStaleTemporaryFiles(options.cache_dir);

  RunSummary run((fs::path(workdir) / "summary.json").string(),
                 {{"raytime_version", Version()},
                  {"pipeline", spec.path},
                  {"name", spec.name},
                  {"workdir", workdir},
                  {"pid", static_cast<int>(::getpid())},
                  {"started_utc", UtcNow()},
                  {"status", "running"},
                  {"stages", json::array()},
                  {"metrics", json::object()},
                  {"guardrails", json::object()},
                  {"pose_sets", json::object()},
                  {"warnings", json::array()}});
  run.Update([](json&) {});
  const auto finish = [&](json& summary, const std::string& status) {
    summary["status"] = status;
    summary["finished_utc"] = UtcNow();
    summary["seconds"] = SecondsSince(run_start);
  };
  const InterruptAction on_interrupt([&](int signal) {
    run.Update([&](json& summary) {
      AppendStaleOutputs(MoveStaleOutputs(spec, workdir, summary["stages"], run.started), &summary);
      finish(summary, "interrupted");
      summary["signal"] = signal;
      summary["error"] =
          "interrupted by signal " + std::to_string(signal) +
          (summary.contains("stage") ? " during stage " + summary["stage"].get<std::string>()
                                     : std::string());
    });
    spdlog::error(fmt::format("interrupted (signal {}); {}", signal,
                              (fs::path(workdir) / "summary.json").string()));
  });

  std::map<std::string, ArtifactSource> artifacts;
  try {
    bool names_checked = false;
    for (size_t i = 0; i < spec.stages.size(); ++i) {
      StopPoint();  // an in-process run's Ctrl-C: the actions above wrote "interrupted"
      StepStage(spec, i, workdir, options, &run, &artifacts);
      if (!names_checked && artifacts.count(kArtifactImages) > 0) {
        names_checked = true;
        CheckImageNamesAhead(spec, i + 1, artifacts.at(kArtifactImages).file);
      }
    }
    StopPoint();
  } catch (const std::exception& e) {
    // A stop requested in-process (core/interrupt.h) already recorded "interrupted"; what failed
    // after it (a temporary file its actions removed) is of the interruption, not a failure.
    if (StopWasRequested()) throw;
    const FailureDescription failure = DescribeFailure(e);
    try {
      run.Update([&](json& summary) {
        AppendStaleOutputs(MoveStaleOutputs(spec, workdir, summary["stages"], run.started),
                           &summary);
        finish(summary, "failed");
        summary["error"] = failure.message;
        summary["cause"] = failure.cause;
      });
    } catch (const std::exception& summary_error) {
      // A full disk fails this write too: the stage's error is the one to report.
      spdlog::error(
          fmt::format("cannot record the failure in summary.json: {}", summary_error.what()));
    }
    WriteReportPage(workdir);
    throw;
  }
  run.Update([&](json& summary) {
    summary.erase("stage");
    finish(summary, summary["warnings"].empty() ? "ok" : "ok_with_warnings");
  });
  const json summary = run.Get();
  WriteReportPage(workdir);
  if (summary["status"] == "ok_with_warnings") {
    spdlog::warn(fmt::format("finished with {} warning(s) (see {}/summary.json)",
                             summary["warnings"].size(), workdir));
  }
  spdlog::info(fmt::format("summary: {}", (fs::path(workdir) / "summary.json").string()));
  return summary;
}

bool RecordCrashedRun(const PipelineSpec& spec, const std::string& workdir, int pid,
                      fs::file_time_type run_start, const std::string& error,
                      const std::string& cause, int signal) {
  const std::string path = (fs::path(workdir) / "summary.json").string();
  std::error_code exists_error;
  if (!fs::exists(path, exists_error)) return false;
  const json previous = json::parse(ReadTextFile(path), nullptr, false);
  if (previous.is_discarded() || previous.value("pid", 0) != pid ||
      previous.value("status", "") != "running") {
    return false;
  }
  RunSummary run(path, previous);
  run.Update([&](json& summary) {
    // What the stages it did not complete had written, in this run or an earlier one: aside, as
    // a failure moves it.
    AppendStaleOutputs(MoveStaleOutputs(spec, workdir, summary["stages"], run_start), &summary);
    summary["status"] = "crashed";
    summary["finished_utc"] = UtcNow();
    summary["error"] = error;
    summary["cause"] = cause;
    if (signal != 0) summary["signal"] = signal;
  });
  WriteReportPage(workdir);
  return true;
}

}  // namespace raytime
