#include "pipelines/pipeline.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>

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

const std::vector<std::string> kTopLevelKeys = {"name", "description", "dataset",
                                                "workdir", "stages", "sweep"};

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  char buffer[32];
  std::strftime(buffer, sizeof(buffer), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return buffer;
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

PipelineStageSpec* FindStage(PipelineSpec* spec, const std::string& type) {
  for (auto& stage : spec->stages) {
    if (stage.type == type) return &stage;
  }
  return nullptr;
}

std::vector<std::string> StageNames(const PipelineSpec& spec) {
  std::vector<std::string> names;
  for (const auto& stage : spec.stages) names.push_back(stage.type);
  return names;
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
    throw InputError(source + " " + dotted_key + ": expected STAGE.KEY (e.g. dataset.root or "
                     "prior.level_deg)");
  }
  const std::string type = dotted_key.substr(0, dot);
  const std::string key = dotted_key.substr(dot + 1);
  PipelineStageSpec* stage = FindStage(spec, type);
  if (!stage) {
    throw InputError(source + " " + dotted_key + ": " +
                     UnknownKeyMessage("this pipeline", type, StageNames(*spec), "stage"));
  }
  const std::vector<std::string> keys = CreateStage(type)->OptionKeys();
  if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
    throw InputError(source + " " + dotted_key + ": " +
                     UnknownKeyMessage("stage '" + type + "'", key, keys));
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

json RunOnce(const PipelineSpec& spec, const std::string& workdir, bool force) {
  const auto run_start = std::chrono::steady_clock::now();
  fs::create_directories(fs::path(workdir) / ".raytime");
  json summary = {{"raytime_version", Version()},
                  {"pipeline", spec.path},
                  {"name", spec.name},
                  {"workdir", workdir},
                  {"started_utc", UtcNow()},
                  {"stages", json::array()},
                  {"metrics", json::object()},
                  {"guardrails", json::object()}};
  const std::string summary_path = (fs::path(workdir) / "summary.json").string();
  std::map<std::string, ArtifactSource> artifacts;
  try {
    for (size_t i = 0; i < spec.stages.size(); ++i) {
      const PipelineStageSpec& stage_spec = spec.stages[i];
      std::unique_ptr<Stage> stage = CreateStage(stage_spec.type);
      stage->Configure(stage_spec.options, spec.path);
      const std::string tag = "[" + std::to_string(i + 1) + "/" +
                              std::to_string(spec.stages.size()) + "] " + stage->type();

      StageContext context;
      context.workdir = workdir;
      context.output_path = (fs::path(workdir) / (stage->type() + ".h5")).string();
      json key_material = {{"type", stage->type()},
                           {"version", Version()},
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
          (fs::path(workdir) / ".raytime" / (stage->type() + ".json")).string();
      bool unchanged = !force && fs::exists(record_path) && fs::exists(context.output_path);
      json record;
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
      json entry = {{"type", stage->type()}, {"key", key}, {"options", stage->OptionsJson()}};
      if (unchanged) {
        spdlog::info("{}: inputs and options unchanged, skipped", tag);
        entry["status"] = "skipped";
        entry["seconds"] = 0.0;
        entry["summary"] = record["summary"];
        entry["previous_seconds"] = record["seconds"];
      } else {
        spdlog::info("{}: {}", tag, stage->description());
        const auto start = std::chrono::steady_clock::now();
        json stage_summary = stage->Run(context);
        const double seconds = SecondsSince(start);
        spdlog::info("{}: done in {:.2f} s", tag, seconds);
        record = {{"key", key}, {"summary", stage_summary}, {"seconds", seconds},
                  {"finished_utc", UtcNow()}};
        WriteTextFileAtomically(record_path, record.dump(2));
        entry["status"] = "ran";
        entry["seconds"] = seconds;
        entry["summary"] = stage_summary;
        produced = ArtifactsIn(context.output_path);
      }
      for (const auto& artifact : produced) {
        artifacts[artifact] = {context.output_path, key};
      }
      if (entry["summary"].contains("metrics")) summary["metrics"].update(entry["summary"]["metrics"]);
      if (entry["summary"].contains("guardrails")) {
        summary["guardrails"][stage->type()] = entry["summary"]["guardrails"];
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

json RunSweep(const PipelineSpec& spec, const std::string& workdir, bool force) {
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
  spdlog::info("sweep: {} runs", combinations.size());
  const auto start = std::chrono::steady_clock::now();
  json rows = json::array();
  int failures = 0;
  for (size_t r = 0; r < combinations.size(); ++r) {
    PipelineSpec run = spec;
    run.sweep.clear();
    std::string label;
    json params = json::object();
    for (size_t axis = 0; axis < spec.sweep.size(); ++axis) {
      const auto& [key, values] = spec.sweep[axis];
      const YAML::Node& value = values[combinations[r][axis]];
      SetOption(&run, key, value, "sweep");
      label += (label.empty() ? "" : ",") + RunLabelPart(key, value);
      params[key] = value.IsScalar() ? value.Scalar() : YAML::Dump(value);
    }
    const std::string run_dir = (fs::path(workdir) / "runs" / label).string();
    spdlog::info("sweep run {}/{}: {}", r + 1, combinations.size(), label);
    json row = {{"run", label}};
    row.update(params);
    try {
      const json run_summary = RunOnce(run, run_dir, force);
      row["status"] = "ok";
      row["seconds"] = run_summary["seconds"];
      FlattenScalars(run_summary["metrics"], "metrics", &row);
    } catch (const std::exception& e) {
      ++failures;
      spdlog::error("sweep run {} failed: {}", label, e.what());
      row["status"] = "failed";
      row["error"] = e.what();
    }
    rows.push_back(row);
    WriteSweepTables(workdir, rows);  // after every run, so an interrupted sweep keeps its rows
  }
  json summary = {{"raytime_version", Version()}, {"pipeline", spec.path},
                  {"name", spec.name},            {"workdir", workdir},
                  {"runs", rows},                 {"failures", failures},
                  {"status", failures ? "failed" : "ok"},
                  {"seconds", SecondsSince(start)}};
  WriteTextFileAtomically((fs::path(workdir) / "summary.json").string(), summary.dump(2));
  if (failures) {
    throw InputError(std::to_string(failures) + " of " + std::to_string(combinations.size()) +
                     " sweep runs failed (see " + workdir + "/sweep.csv)");
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
    const std::string key = entry.first.as<std::string>();
    if (std::find(kTopLevelKeys.begin(), kTopLevelKeys.end(), key) == kTopLevelKeys.end()) {
      ThrowInput(path, YamlLine(entry.first),
                 UnknownKeyMessage("the pipeline's top level", key, kTopLevelKeys));
    }
  }
  PipelineSpec spec;
  spec.path = path;
  spec.name = root["name"] ? root["name"].as<std::string>() : fs::path(path).stem().string();
  spec.workdir = root["workdir"] ? root["workdir"].as<std::string>() : "";
  if (!root["dataset"]) ThrowInput(path, 0, "the pipeline has no 'dataset' section");
  spec.stages.push_back({"dataset", root["dataset"], YamlLine(root["dataset"])});

  const YAML::Node stages = root["stages"];
  if (stages && !stages.IsSequence()) {
    ThrowInput(path, YamlLine(stages), "'stages' must be a list of stage entries");
  }
  for (const auto& entry : stages) {
    PipelineStageSpec stage;
    stage.line = YamlLine(entry);
    if (entry.IsScalar()) {
      stage.type = entry.as<std::string>();
      stage.options = YAML::Node(YAML::NodeType::Map);
    } else if (entry.IsMap() && entry.size() == 1) {
      stage.type = entry.begin()->first.as<std::string>();
      stage.options = entry.begin()->second;
    } else {
      ThrowInput(path, stage.line,
                 "a stage entry must be a stage name or '- NAME: {options}' with one name");
    }
    if (stage.type == "dataset") {
      ThrowInput(path, stage.line, "'dataset' is configured in its own top-level section");
    }
    std::vector<std::string> types = StageTypes();
    types.erase(types.begin());  // "dataset"
    if (std::find(types.begin(), types.end(), stage.type) == types.end()) {
      ThrowInput(path, stage.line, UnknownKeyMessage("the pipeline", stage.type, types, "stage"));
    }
    if (FindStage(&spec, stage.type)) {
      ThrowInput(path, stage.line, "stage '" + stage.type + "' appears twice");
    }
    spec.stages.push_back(stage);
  }
  for (const auto& stage : spec.stages) ValidateStage(stage, path);

  if (const YAML::Node sweep = root["sweep"]) {
    if (!sweep.IsMap()) ThrowInput(path, YamlLine(sweep), "'sweep' must map STAGE.KEY to lists");
    for (const auto& axis : sweep) {
      const std::string key = axis.first.as<std::string>();
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
  if (!spec.sweep.empty()) return RunSweep(spec, workdir, options.force);
  return RunOnce(spec, workdir, options.force);
}

}  // namespace raytime
