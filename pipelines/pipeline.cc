#include "pipelines/pipeline.h"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/options.h"
#include "core/version.h"
#include "pipelines/content_hash.h"
#include "pipelines/stage.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// XXH3 of this executable's file, computed once per process.
const std::string& ExecutableHash() {
  static const std::string hash = HashFileContents(fs::read_symlink("/proc/self/exe").string());
  return hash;
}

const std::vector<std::string> kTopLevelKeys = {"name",    "description", "dataset",
                                                "workdir", "stages",      "sweep"};

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  char buffer[32];
  std::strftime(buffer, sizeof(buffer), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return buffer;
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

PipelineStageSpec* FindStage(PipelineSpec* spec, const std::string& id) {
  for (auto& stage : spec->stages) {
    if (stage.id == id) return &stage;
  }
  return nullptr;
}

std::vector<std::string> StageIds(const PipelineSpec& spec) {
  std::vector<std::string> ids;
  for (const auto& stage : spec.stages) ids.push_back(stage.id);
  return ids;
}

// The text of a node where the pipeline wants a name, key or path. YAML allows a list or mapping
// there too, which as<std::string>() would reject with yaml-cpp's own exception.
std::string ScalarText(const YAML::Node& node, const std::string& path, const std::string& what) {
  if (node.IsMap() || node.IsSequence()) {
    ThrowInput(path, YamlLine(node),
               what + " must be a single value, not a " + (node.IsMap() ? "mapping" : "list"));
  }
  return node.as<std::string>();
}

// Validates the options of one stage entry by configuring a throwaway stage.
void ValidateStage(const PipelineStageSpec& stage, const std::string& path) {
  CreateStage(stage.type)->Configure(stage.options, path);
}

// Sets `stage.key` to `value`, naming `source` ("--set", "sweep") in errors.
void SetOption(PipelineSpec* spec, const std::string& dotted_key, const YAML::Node& value,
               const std::string& source) {
  const size_t dot = dotted_key.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == dotted_key.size()) {
    throw InputError(source + " " + dotted_key +
                     ": expected STAGE.KEY (e.g. dataset.root or "
                     "prior.level_deg)");
  }
  const std::string id = dotted_key.substr(0, dot);
  const std::string key = dotted_key.substr(dot + 1);
  PipelineStageSpec* stage = FindStage(spec, id);
  if (!stage) {
    throw InputError(source + " " + dotted_key + ": " +
                     UnknownKeyMessage("this pipeline", id, StageIds(*spec), "stage"));
  }
  const std::vector<std::string> keys = CreateStage(stage->type)->OptionKeys();
  if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
    throw InputError(source + " " + dotted_key + ": " +
                     UnknownKeyMessage("stage '" + id + "'", key, keys));
  }
  stage->options = YAML::Clone(stage->options);
  if (!stage->options.IsMap()) stage->options = YAML::Node(YAML::NodeType::Map);
  stage->options[key] = YAML::Clone(value);
  ValidateStage(*stage, source + " " + dotted_key);
}

// Artifacts found in a stage's HDF5 output.
std::vector<std::string> ArtifactsIn(const std::string& path) {
  const Hdf5Reader reader(path);
  std::vector<std::string> artifacts;
  if (reader.HasImages()) artifacts.push_back(kArtifactImages);
  for (const auto& name : reader.PoseSetNames()) artifacts.push_back(PoseArtifact(name));
  if (reader.HasFeatures()) artifacts.push_back("features");
  if (reader.HasMatches()) artifacts.push_back("matches");
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

struct StageRecord {
  std::string key;
  json summary;
  double seconds = 0.0;
};

json RecordJson(const StageRecord& record) {
  return {{"key", record.key},
          {"summary", record.summary},
          {"seconds", record.seconds},
          {"finished_utc", UtcNow()}};
}

json RunOnce(const PipelineSpec& spec, const std::string& workdir, const RunOptions& options) {
  const auto run_start = std::chrono::steady_clock::now();
  fs::create_directories(fs::path(workdir) / ".raytime");
  json summary = {
      {"raytime_version", Version()}, {"pipeline", spec.path},       {"name", spec.name},
      {"workdir", workdir},           {"started_utc", UtcNow()},     {"stages", json::array()},
      {"metrics", json::object()},    {"guardrails", json::object()}};
  const std::string summary_path = (fs::path(workdir) / "summary.json").string();
  std::map<std::string, ArtifactSource> artifacts;
  try {
    for (size_t i = 0; i < spec.stages.size(); ++i) {
      const PipelineStageSpec& stage_spec = spec.stages[i];
      std::unique_ptr<Stage> stage = CreateStage(stage_spec.type);
      stage->Configure(stage_spec.options, spec.path);
      const std::string tag = "[" + std::to_string(i + 1) + "/" +
                              std::to_string(spec.stages.size()) + "] " + stage_spec.id;

      StageContext context;
      context.stage_id = stage_spec.id;
      context.workdir = workdir;
      context.output_path = (fs::path(workdir) / (stage_spec.id + ".h5")).string();
      // The key names the id too: "refine@gnc" writes pose set "refined@gnc", not "refined".
      // It also names the executable's contents, so a rebuilt raytime never reuses a stage
      // output computed by different code (the version string alone does not change between
      // development builds).
      json key_material = {{"id", stage_spec.id},
                           {"version", Version()},
                           {"executable", ExecutableHash()},
                           {"options", stage->OptionsJson()},
                           {"inputs", json::object()},
                           {"external", json::object()}};
      for (const auto& input : stage->Inputs()) {
        const auto it = artifacts.find(input);
        key_material["inputs"][input] = it == artifacts.end() ? "" : it->second.stage_key;
      }
      for (const auto& [artifact, source] : artifacts) context.artifacts[artifact] = source.file;
      for (const auto& file : stage->ExternalFiles()) {
        key_material["external"][file] = HashFileContents(file);
      }
      const std::string key = HashBytes(key_material.dump());
      const std::string record_path =
          (fs::path(workdir) / ".raytime" / (stage_spec.id + ".json")).string();

      // 1. This work directory already holds the result.
      json record;
      bool unchanged = !options.force && fs::exists(record_path) && fs::exists(context.output_path);
      if (unchanged) {
        record = json::parse(ReadTextFile(record_path), nullptr, false);
        unchanged = !record.is_discarded() && record.value("key", "") == key;
        for (const auto& extra : stage->ExtraOutputs()) {
          unchanged = unchanged && fs::exists(fs::path(workdir) / extra);
        }
      }
      std::vector<std::string> produced;
      if (unchanged) {
        try {
          produced = ArtifactsIn(context.output_path);
        } catch (const InputError& e) {
          spdlog::warn("{}: previous output is unreadable, rerunning ({})", tag, e.what());
          unchanged = false;
        }
      }
      json entry = {{"id", stage_spec.id},
                    {"type", stage_spec.type},
                    {"key", key},
                    {"options", stage->OptionsJson()}};
      if (unchanged) {
        spdlog::info("{}: inputs and options unchanged, skipped", tag);
        entry["status"] = "skipped";
        entry["seconds"] = 0.0;
        entry["summary"] = record["summary"];
        entry["previous_seconds"] = record["seconds"];
      } else {
        // 2. Another run computed it (sweeps share a cache); stages that write folders besides
        // their HDF5 file always run.
        const bool cacheable = !options.cache_dir.empty() && stage->ExtraOutputs().empty();
        std::unique_ptr<CacheLock> lock;
        const fs::path cached = fs::path(options.cache_dir) / key;
        if (cacheable) lock = std::make_unique<CacheLock>(options.cache_dir, key);
        if (cacheable && !options.force && fs::exists(cached / "record.json")) {
          spdlog::info("{}: computed by another run, taken from the cache", tag);
          record = json::parse(ReadTextFile((cached / "record.json").string()));
          LinkOrCopy(cached / "output.h5", context.output_path);
          entry["status"] = "cached";
          entry["seconds"] = 0.0;
          entry["previous_seconds"] = record["seconds"];
        } else {
          // 3. Run it.
          spdlog::info("{}: {}", tag, stage->description());
          const auto start = std::chrono::steady_clock::now();
          StageRecord fresh{key, stage->Run(context), 0.0};
          fresh.seconds = SecondsSince(start);
          spdlog::info("{}: done in {:.2f} s", tag, fresh.seconds);
          record = RecordJson(fresh);
          entry["status"] = "ran";
          entry["seconds"] = fresh.seconds;
          if (cacheable) {
            WriteDirectoryAtomically(cached.string(), [&](const std::string& dir) {
              LinkOrCopy(context.output_path, fs::path(dir) / "output.h5");
              WriteTextFileAtomically((fs::path(dir) / "record.json").string(), record.dump(2));
            });
          }
        }
        WriteTextFileAtomically(record_path, record.dump(2));
        entry["summary"] = record["summary"];
        produced = ArtifactsIn(context.output_path);
      }
      for (const auto& artifact : produced) {
        artifacts[artifact] = {context.output_path, key};
      }
      if (entry["summary"].contains("metrics")) {
        summary["metrics"].update(entry["summary"]["metrics"]);
      }
      if (entry["summary"].contains("guardrails")) {
        summary["guardrails"][stage_spec.id] = entry["summary"]["guardrails"];
      }
      summary["stages"].push_back(entry);
    }
    summary["status"] = "ok";
  } catch (const std::exception& e) {
    summary["status"] = "failed";
    summary["error"] = e.what();
    summary["finished_utc"] = UtcNow();
    summary["seconds"] = SecondsSince(run_start);
    WriteTextFileAtomically(summary_path, summary.dump(2));
    throw;
  }
  summary["finished_utc"] = UtcNow();
  summary["seconds"] = SecondsSince(run_start);
  WriteTextFileAtomically(summary_path, summary.dump(2));
  spdlog::info("summary: {}", summary_path);
  return summary;
}

// "prior.level_deg" -> "level_deg"; a path value -> its last component.
std::string RunLabelPart(const std::string& key, const YAML::Node& value) {
  std::string text = value.IsScalar() ? value.Scalar() : YAML::Dump(value);
  if (text.find('/') != std::string::npos) text = fs::path(text).filename().string();
  std::string label = key.substr(key.find('.') + 1) + "=" + text;
  for (char& c : label) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_' &&
        c != '=') {
      c = '_';
    }
  }
  return label;
}

// Scalar metrics as flat columns: metrics.<poses>.<alignment>.<field>.
void FlattenScalars(const json& value, const std::string& prefix, json* row) {
  if (value.is_object()) {
    for (const auto& [key, child] : value.items()) {
      FlattenScalars(child, prefix.empty() ? key : prefix + "." + key, row);
    }
  } else if (value.is_primitive()) {
    (*row)[prefix] = value;
  }
}

std::string CsvField(const json& value) {
  std::string text = value.is_string() ? value.get<std::string>() : value.dump();
  if (text.find_first_of(",\"\n") != std::string::npos) {
    std::string quoted = "\"";
    for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
    return quoted + "\"";
  }
  return text;
}

void WriteSweepTables(const std::string& workdir, const json& rows) {
  std::vector<std::string> columns;
  for (const auto& row : rows) {
    for (const auto& [key, value] : row.items()) {
      if (std::find(columns.begin(), columns.end(), key) == columns.end()) columns.push_back(key);
    }
  }
  std::string csv;
  for (size_t c = 0; c < columns.size(); ++c) csv += (c ? "," : "") + columns[c];
  csv += "\n";
  for (const auto& row : rows) {
    for (size_t c = 0; c < columns.size(); ++c) {
      csv += (c ? "," : "") + (row.contains(columns[c]) ? CsvField(row[columns[c]]) : "");
    }
    csv += "\n";
  }
  WriteTextFileAtomically((fs::path(workdir) / "sweep.csv").string(), csv);
  WriteTextFileAtomically((fs::path(workdir) / "sweep.json").string(), rows.dump(2));
}

// A sweep run in its own process: `raytime run RUN_DIR/pipeline.yaml --workdir RUN_DIR
// --cache-dir CACHE`, output to RUN_DIR/run.log.
pid_t SpawnRun(const std::string& run_dir, const std::string& cache_dir, bool force) {
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  const std::string pipeline = (fs::path(run_dir) / "pipeline.yaml").string();
  const std::string log = (fs::path(run_dir) / "run.log").string();
  std::vector<std::string> args = {self,    "run",         pipeline, "--workdir",
                                   run_dir, "--cache-dir", cache_dir};
  if (force) args.push_back("--force");
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("cannot start a sweep run: fork failed");
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_CREAT | O_WRONLY | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
      ::close(fd);
    }
    std::vector<char*> argv;
    for (auto& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    ::execv(self.c_str(), argv.data());
    ::_exit(127);
  }
  return pid;
}

json SweepRow(const std::string& label, const json& params, const std::string& run_dir) {
  json row = {{"run", label}};
  row.update(params);
  const fs::path summary_path = fs::path(run_dir) / "summary.json";
  const json summary = fs::exists(summary_path)
                           ? json::parse(ReadTextFile(summary_path.string()), nullptr, false)
                           : json();
  if (summary.is_discarded() || summary.is_null()) {
    row["status"] = "failed";
    row["error"] = "no summary.json (see " + run_dir + "/run.log)";
    return row;
  }
  row["status"] = summary.value("status", "failed");
  if (summary.contains("error")) row["error"] = summary["error"];
  row["seconds"] = summary.value("seconds", 0.0);
  for (const auto& stage : summary["stages"]) {
    // Time of the stage's own computation, also when this run reused it.
    const double seconds = stage["status"] == "ran" ? stage["seconds"].get<double>()
                                                    : stage.value("previous_seconds", 0.0);
    row["seconds." + stage["id"].get<std::string>()] = seconds;
  }
  FlattenScalars(summary["metrics"], "metrics", &row);
  FlattenScalars(summary["guardrails"], "guardrails", &row);
  return row;
}

json RunSweep(const PipelineSpec& spec, const std::string& workdir, const RunOptions& options) {
  std::vector<std::vector<size_t>> combinations = {{}};
  for (const auto& [key, values] : spec.sweep) {
    std::vector<std::vector<size_t>> expanded;
    for (const auto& prefix : combinations) {
      for (size_t v = 0; v < values.size(); ++v) {
        expanded.push_back(prefix);
        expanded.back().push_back(v);
      }
    }
    combinations = std::move(expanded);
  }
  const int jobs = options.jobs > 0
                       ? options.jobs
                       : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const std::string cache_dir =
      options.cache_dir.empty() ? (fs::path(workdir) / "cache").string() : options.cache_dir;
  spdlog::info("sweep: {} runs, {} at a time, cache {}", combinations.size(), jobs, cache_dir);

  struct Run {
    std::string label;
    std::string dir;
    json params;
  };
  std::vector<Run> runs;
  for (const auto& combination : combinations) {
    PipelineSpec run_spec = spec;
    run_spec.sweep.clear();
    Run run;
    run.params = json::object();
    for (size_t axis = 0; axis < spec.sweep.size(); ++axis) {
      const auto& [key, values] = spec.sweep[axis];
      const YAML::Node& value = values[combination[axis]];
      SetOption(&run_spec, key, value, "sweep");
      run.label += (run.label.empty() ? "" : ",") + RunLabelPart(key, value);
      run.params[key] = value.IsScalar() ? value.Scalar() : YAML::Dump(value);
    }
    run.dir = (fs::path(workdir) / "runs" / run.label).string();
    fs::create_directories(run.dir);
    WriteTextFileAtomically((fs::path(run.dir) / "pipeline.yaml").string(),
                            PipelineToYaml(run_spec));
    runs.push_back(std::move(run));
  }

  const auto start = std::chrono::steady_clock::now();
  std::vector<json> rows(runs.size());
  std::map<pid_t, size_t> running;
  size_t next = 0, done = 0;
  int failures = 0;
  auto write_tables = [&]() {
    json table = json::array();
    for (const auto& row : rows) {
      if (!row.is_null()) table.push_back(row);
    }
    WriteSweepTables(workdir, table);
  };
  while (done < runs.size()) {
    while (next < runs.size() && static_cast<int>(running.size()) < jobs) {
      running[SpawnRun(runs[next].dir, cache_dir, options.force)] = next;
      ++next;
    }
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);
    if (pid < 0) throw std::runtime_error("sweep: waitpid failed");
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const size_t index = it->second;
    running.erase(it);
    ++done;
    rows[index] = SweepRow(runs[index].label, runs[index].params, runs[index].dir);
    if (rows[index]["status"] != "ok") ++failures;
    spdlog::info("sweep: {}/{} {} {} ({:.1f} s)", done, runs.size(), runs[index].label,
                 rows[index]["status"].get<std::string>(), rows[index].value("seconds", 0.0));
    if (rows[index]["status"] != "ok") {
      spdlog::error("sweep run {} failed: {}", runs[index].label,
                    rows[index].value("error", std::string("see run.log")));
    }
    write_tables();  // after every run, so an interrupted sweep keeps its rows
  }
  json summary = {{"raytime_version", Version()},
                  {"pipeline", spec.path},
                  {"name", spec.name},
                  {"workdir", workdir},
                  {"runs", rows},
                  {"failures", failures},
                  {"status", failures ? "failed" : "ok"},
                  {"seconds", SecondsSince(start)}};
  WriteTextFileAtomically((fs::path(workdir) / "summary.json").string(), summary.dump(2));
  if (failures) {
    throw InputError(std::to_string(failures) + " of " + std::to_string(runs.size()) +
                     " sweep runs failed (see " + workdir + "/sweep.csv and each run.log)");
  }
  return summary;
}

}  // namespace

PipelineSpec LoadPipeline(const std::string& path) {
  if (!fs::exists(path)) ThrowInput(path, 0, "pipeline file not found");
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::ParserException& e) {
    ThrowInput(path, e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) ThrowInput(path, 0, "a pipeline file must be a YAML mapping");
  for (const auto& entry : root) {
    const std::string key = ScalarText(entry.first, path, "a top-level key");
    if (std::find(kTopLevelKeys.begin(), kTopLevelKeys.end(), key) == kTopLevelKeys.end()) {
      ThrowInput(path, YamlLine(entry.first),
                 UnknownKeyMessage("the pipeline's top level", key, kTopLevelKeys));
    }
  }
  PipelineSpec spec;
  spec.path = path;
  spec.name =
      root["name"] ? ScalarText(root["name"], path, "'name'") : fs::path(path).stem().string();
  spec.workdir = root["workdir"] ? ScalarText(root["workdir"], path, "'workdir'") : "";
  if (!root["dataset"]) ThrowInput(path, 0, "the pipeline has no 'dataset' section");
  spec.stages.push_back({"dataset", "dataset", root["dataset"], YamlLine(root["dataset"])});

  const YAML::Node stages = root["stages"];
  if (stages && !stages.IsSequence()) {
    ThrowInput(path, YamlLine(stages), "'stages' must be a list of stage entries");
  }
  for (const auto& entry : stages) {
    PipelineStageSpec stage;
    stage.line = YamlLine(entry);
    if (entry.IsScalar()) {
      stage.id = entry.as<std::string>();
      stage.options = YAML::Node(YAML::NodeType::Map);
    } else if (entry.IsMap() && entry.size() == 1) {
      stage.id = ScalarText(entry.begin()->first, path, "a stage name");
      stage.options = entry.begin()->second;
    } else {
      ThrowInput(path, stage.line,
                 "a stage entry must be a stage name or '- NAME: {options}' with one name");
    }
    stage.type = StageTypeOfId(stage.id);
    const std::string suffix = stage.id.substr(stage.type.size());
    if (!suffix.empty() && (suffix.size() < 2 ||
                            suffix.find_first_not_of(
                                "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-",
                                1) != std::string::npos)) {
      ThrowInput(path, stage.line,
                 "stage id '" + stage.id + "': after '@' use letters, digits, '_' or '-'");
    }
    if (stage.type == "dataset") {
      ThrowInput(path, stage.line, "'dataset' is configured in its own top-level section");
    }
    std::vector<std::string> types = StageTypes();
    types.erase(types.begin());  // "dataset"
    if (std::find(types.begin(), types.end(), stage.type) == types.end()) {
      ThrowInput(path, stage.line, UnknownKeyMessage("the pipeline", stage.type, types, "stage"));
    }
    if (FindStage(&spec, stage.id)) {
      ThrowInput(
          path, stage.line,
          "stage '" + stage.id + "' appears twice (name a second one '" + stage.type + "@NAME')");
    }
    spec.stages.push_back(stage);
  }
  for (const auto& stage : spec.stages) ValidateStage(stage, path);

  if (const YAML::Node sweep = root["sweep"]) {
    if (!sweep.IsMap()) ThrowInput(path, YamlLine(sweep), "'sweep' must map STAGE.KEY to lists");
    for (const auto& axis : sweep) {
      const std::string key = ScalarText(axis.first, path, "a sweep key");
      if (!axis.second.IsSequence() || axis.second.size() == 0) {
        ThrowInput(path, YamlLine(axis.second), "sweep." + key + " must be a non-empty list");
      }
      std::vector<YAML::Node> values(axis.second.begin(), axis.second.end());
      PipelineSpec probe = spec;  // validates key and every value's type
      for (const auto& value : values) {
        try {
          SetOption(&probe, key, value, "sweep");
        } catch (const InputError& e) {
          ThrowInput(path, YamlLine(value), e.what());
        }
      }
      spec.sweep.emplace_back(key, std::move(values));
    }
  }
  return spec;
}

std::string PipelineToYaml(const PipelineSpec& spec) {
  YAML::Node root(YAML::NodeType::Map);
  root["name"] = spec.name;
  root["dataset"] = YAML::Clone(spec.stages.front().options);
  YAML::Node stages(YAML::NodeType::Sequence);
  for (size_t i = 1; i < spec.stages.size(); ++i) {
    YAML::Node entry(YAML::NodeType::Map);
    entry[spec.stages[i].id] = YAML::Clone(spec.stages[i].options);
    stages.push_back(entry);
  }
  root["stages"] = stages;
  YAML::Emitter out;
  out << root;
  return std::string(out.c_str()) + "\n";
}

void ApplyOverride(PipelineSpec* spec, const std::string& assignment) {
  const size_t eq = assignment.find('=');
  if (eq == std::string::npos) {
    throw InputError("--set " + assignment + ": expected STAGE.KEY=VALUE");
  }
  YAML::Node value;
  try {
    value = YAML::Load(assignment.substr(eq + 1));
  } catch (const YAML::Exception& e) {
    throw InputError("--set " + assignment + ": value is not valid YAML: " + e.msg);
  }
  SetOption(spec, assignment.substr(0, eq), value, "--set");
}

json RunPipeline(const PipelineSpec& spec, const RunOptions& options) {
  const std::string workdir = !options.workdir.empty() ? options.workdir : spec.workdir;
  if (workdir.empty()) {
    throw InputError(spec.path + ": no work directory (set 'workdir' or pass --workdir)");
  }
  if (!spec.sweep.empty()) return RunSweep(spec, workdir, options);
  return RunOnce(spec, workdir, options);
}

}  // namespace raytime
