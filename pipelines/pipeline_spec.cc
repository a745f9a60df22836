#include "pipelines/pipeline_spec.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>

#include "core/error.h"
#include "core/options.h"
#include "core/user_paths.h"
#include "pipelines/stage.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

const std::vector<std::string> kTopLevelKeys = {"name",    "description", "dataset",
                                                "workdir", "stages",      "sweep"};

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
// there too, which as<std::string>() would reject with yaml-cpp's own exception; names and paths
// go into summary.json, so they must be UTF-8.
std::string ScalarText(const YAML::Node& node, const std::string& path, const std::string& what) {
  if (node.IsMap() || node.IsSequence()) {
    ThrowInput(path, YamlLine(node),
               what + " must be a single value, not a " + (node.IsMap() ? "mapping" : "list"));
  }
  std::string text = node.as<std::string>();
  RequireUtf8(text, path, YamlLine(node), what);
  return text;
}

// The last `count` components of a path, joined by '_'.
std::string LastComponents(const std::string& path, size_t count) {
  std::vector<std::string> parts;
  for (const fs::path& part : fs::path(path).lexically_normal()) {
    if (!part.empty() && part != "/") parts.push_back(part.string());
  }
  std::string text;
  for (size_t i = parts.size() - std::min(count, parts.size()); i < parts.size(); ++i) {
    text += (text.empty() ? "" : "_") + parts[i];
  }
  return text;
}

// Each value of one sweep axis as its run labels show it: a path by its last component, or as
// many last components as tell the axis's paths apart (two datasets both named fountain-P11 in
// different folders wrote their runs into one directory, the second read as the first, done).
std::vector<std::string> AxisLabelTexts(const std::vector<YAML::Node>& values) {
  std::vector<std::string> full;
  for (const YAML::Node& value : values) {
    full.push_back(value.IsScalar() ? value.Scalar() : YAML::Dump(value));
  }
  for (size_t count = 1;; ++count) {
    std::vector<std::string> texts;
    bool longest = true;
    for (const std::string& text : full) {
      const bool path = text.find('/') != std::string::npos;
      texts.push_back(path ? LastComponents(text, count) : text);
      longest = longest && (!path || LastComponents(text, count + 1) == texts.back());
    }
    std::vector<std::string> sorted = texts;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end() || longest) return texts;
  }
}

// "prior.level_deg" -> "level_deg=4" (`text`: the value as AxisLabelTexts shows it).
std::string RunLabelPart(const std::string& key, const std::string& text) {
  std::string label = key.substr(key.find('.') + 1) + "=" + text;
  for (char& c : label) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_' &&
        c != '=') {
      c = '_';
    }
  }
  return label;
}

PipelineStageSpec ParseStageEntry(const YAML::Node& entry, const std::string& path) {
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
  if (!suffix.empty() &&
      (suffix.size() < 2 ||
       suffix.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-",
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
  return stage;
}

}  // namespace

void SetStageOption(PipelineSpec* spec, const std::string& dotted_key, const YAML::Node& value,
                    const std::string& source) {
  const size_t dot = dotted_key.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == dotted_key.size()) {
    throw InputError(source + " " + dotted_key +
                     ": expected STAGE.KEY (e.g. dataset.root or prior.level_deg)");
  }
  const std::string id = dotted_key.substr(0, dot);
  const std::string key = dotted_key.substr(dot + 1);
  PipelineStageSpec* stage = FindStage(spec, id);
  if (!stage) {
    throw InputError(source + " " + dotted_key + ": " +
                     UnknownKeyMessage("this pipeline", id, StageIds(*spec), "stage"));
  }
  YAML::Node single(YAML::NodeType::Map);
  single[key] = YAML::Clone(value);
  try {
    CreateStage(stage->type)->CheckOverride(single, source + " " + dotted_key);
  } catch (const InputError& e) {
    // Unknown keys name the stage id ("refine@gnc"), not only its type. The override's own
    // location ("--set prior.seed:1: ", its line in the one-line value) is said once, without the
    // line.
    const std::string where = source + " " + dotted_key;
    std::string message = e.what();
    if (message.rfind(where + ":", 0) == 0) {
      size_t end = where.size() + 1;
      while (end < message.size() && std::isdigit(static_cast<unsigned char>(message[end]))) ++end;
      if (end < message.size() && message[end] == ':') ++end;
      while (end < message.size() && message[end] == ' ') ++end;
      message = message.substr(end);
    }
    throw InputError(where + ": " + message);
  }
  stage->options = YAML::Clone(stage->options);
  if (!stage->options.IsMap()) stage->options = YAML::Node(YAML::NodeType::Map);
  stage->options[key] = YAML::Clone(value);
}

PipelineSpec LoadPipeline(const std::string& path) {
  if (!fs::exists(path)) ThrowInput(path, 0, "pipeline file not found");
  const YAML::Node root = LoadYamlFile(path);
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
  spec.workdir = root["workdir"] ? ExpandUser(ScalarText(root["workdir"], path, "'workdir'")) : "";
  if (!root["dataset"]) ThrowInput(path, 0, "the pipeline has no 'dataset' section");
  spec.stages.push_back({"dataset", "dataset", root["dataset"], YamlLine(root["dataset"])});

  const YAML::Node stages = root["stages"];
  if (stages && !stages.IsSequence()) {
    ThrowInput(path, YamlLine(stages), "'stages' must be a list of stage entries");
  }
  for (const auto& entry : stages) {
    PipelineStageSpec stage = ParseStageEntry(entry, path);
    if (FindStage(&spec, stage.id)) {
      ThrowInput(
          path, stage.line,
          "stage '" + stage.id + "' appears twice (name a second one '" + stage.type + "@NAME')");
    }
    spec.stages.push_back(stage);
  }
  for (const auto& stage : spec.stages) {
    CreateStage(stage.type)->CheckKeysAndTypes(stage.options, path);
  }

  if (const YAML::Node sweep = root["sweep"]) {
    if (!sweep.IsMap()) ThrowInput(path, YamlLine(sweep), "'sweep' must map STAGE.KEY to lists");
    for (const auto& axis : sweep) {
      const std::string key = ScalarText(axis.first, path, "a sweep key");
      if (!axis.second.IsSequence() || axis.second.size() == 0) {
        ThrowInput(path, YamlLine(axis.second), "sweep." + key + " must be a non-empty list");
      }
      std::vector<YAML::Node> values(axis.second.begin(), axis.second.end());
      PipelineSpec probe = spec;  // checks the key and every value's type
      for (const auto& value : values) {
        try {
          SetStageOption(&probe, key, value, "sweep");
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
  SetStageOption(spec, assignment.substr(0, eq), value, "--set");
}

void ValidatePipeline(const PipelineSpec& spec) {
  for (const auto& stage : spec.stages) {
    try {
      CreateStage(stage.type)->Configure(stage.options, spec.path);
    } catch (const InputError& e) {
      const std::string message = e.what();
      if (message.rfind(spec.path + ":", 0) == 0) throw;
      ThrowInput(spec.path, stage.line, message);
    }
  }
}

std::vector<SweepRun> ExpandSweep(const PipelineSpec& spec) {
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
  std::vector<std::vector<std::string>> label_texts;
  for (const auto& [key, values] : spec.sweep) label_texts.push_back(AxisLabelTexts(values));
  std::vector<SweepRun> runs;
  for (const auto& combination : combinations) {
    SweepRun run;
    run.spec = spec;
    run.spec.sweep.clear();
    for (size_t axis = 0; axis < spec.sweep.size(); ++axis) {
      const auto& [key, values] = spec.sweep[axis];
      const YAML::Node& value = values[combination[axis]];
      SetStageOption(&run.spec, key, value, "sweep");
      run.label +=
          (run.label.empty() ? "" : ",") + RunLabelPart(key, label_texts[axis][combination[axis]]);
      run.swept.emplace_back(key, value.IsScalar() ? value.Scalar() : YAML::Dump(value));
    }
    try {
      ValidatePipeline(run.spec);
    } catch (const InputError& e) {
      throw InputError("sweep run " + run.label + ": " + e.what());
    }
    runs.push_back(std::move(run));
  }
  std::map<std::string, size_t> seen;
  for (size_t r = 0; r < runs.size(); ++r) {
    const auto [it, inserted] = seen.emplace(runs[r].label, r);
    if (!inserted) {
      throw InputError("sweep: runs " + std::to_string(it->second + 1) + " and " +
                       std::to_string(r + 1) + " are both '" + runs[r].label +
                       "' (a value listed twice?): each run needs its own directory");
    }
  }
  return runs;
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

}  // namespace raytime
