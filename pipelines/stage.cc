#include "pipelines/stage.h"

#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "core/error.h"
#include "core/hdf5_store.h"

namespace raytime {

bool StageContext::ReadPreviousOutput(const std::function<void(const Hdf5Reader&)>& read,
                                      const std::string& fallback) const {
  if (previous_output.empty()) return false;
  try {
    read(Hdf5Reader(previous_output));
  } catch (const std::exception& e) {
    spdlog::warn(fmt::format("{}: the previous run's output {} cannot be reused ({}); {}", stage_id,
                             previous_output, e.what(), fallback));
    return false;
  }
  return true;
}

const std::string& StageContext::Require(const std::string& artifact) const {
  const auto it = artifacts.find(artifact);
  if (it == artifacts.end()) {
    std::string have;
    for (const auto& [name, file] : artifacts) have += (have.empty() ? "" : ", ") + name;
    throw MissingArtifactError(
        "this stage needs '" + artifact +
        "', which no earlier stage produced (available: " + (have.empty() ? "none" : have) + ")");
  }
  return it->second;
}

std::string StageContext::OutputPoseSetName(const std::string& base) const {
  const size_t at = stage_id.find('@');
  return at == std::string::npos ? base : base + stage_id.substr(at);
}

std::string StageTypeOfId(const std::string& stage_id) {
  return stage_id.substr(0, stage_id.find('@'));
}

std::vector<std::string> Stage::OptionKeys() {
  std::vector<std::string> keys;
  for (const OptionDoc& doc : OptionDocs()) keys.push_back(doc.key);
  return keys;
}

void Stage::BindCli(CLI::App* app) {
  cli_docs_ = OptionDocs();
  const size_t num_options = cli_docs_.size();
  for (const OptionAlias& alias : DeprecatedAliases()) {
    OptionDoc doc;
    doc.key = alias.old_key;
    doc.type = "BOOL";
    doc.default_value = "false";
    doc.description = "Deprecated: --" + alias.new_key + " " + alias.value;
    doc.is_bool = true;
    cli_docs_.push_back(doc);
  }
  for (size_t i = 0; i < cli_docs_.size(); ++i) {
    const OptionDoc& doc = cli_docs_[i];
    CLI::Option* option = app->add_option("--" + doc.key, cli_values_[doc.key], doc.HelpText());
    option->default_str(doc.default_value)->type_name(doc.type);
    if (!doc.is_list) option->expected(1);
    if (i >= num_options) option->group("");  // accepted, not advertised
  }
}

namespace {

// A command-line value as YAML: "1e-3" -> number, "[1, 2]" -> list; text options as written.
YAML::Node ParseCliValue(const std::string& text, bool is_text) {
  if (is_text && !(text.size() >= 2 && text.front() == '[' && text.back() == ']')) {
    return YAML::Node(text);
  }
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception&) {
    return YAML::Node(text);
  }
}

}  // namespace

YAML::Node Stage::CliOptions() const {
  YAML::Node node(YAML::NodeType::Map);
  for (const OptionDoc& doc : cli_docs_) {
    const std::vector<std::string>& values = cli_values_.at(doc.key);
    if (values.empty()) continue;
    const bool is_text = doc.type == "TEXT";
    if (!doc.is_list) {
      node[doc.key] = ParseCliValue(values.front(), is_text && !doc.is_list);
      continue;
    }
    // `--gnc_scales 1e4 1e3` or `--gnc_scales "[1e4, 1e3]"` (`[]` for an empty list).
    const YAML::Node first = ParseCliValue(values.front(), false);
    if (values.size() == 1 && first.IsSequence()) {
      node[doc.key] = first;
      continue;
    }
    YAML::Node list(YAML::NodeType::Sequence);
    for (const auto& value : values) list.push_back(ParseCliValue(value, is_text));
    node[doc.key] = list;
  }
  return node;
}

}  // namespace raytime

#include "core/hdf5_store.h"
#include "pipelines/stages.h"

namespace raytime {

std::vector<std::string> StageTypes() {
  return {"dataset", "features",  "matches",  "colmap_import", "bootstrap", "prior",
          "refine",  "classical", "evaluate", "export",        "splat"};
}

std::unique_ptr<Stage> CreateStage(const std::string& type) {
  if (type == "dataset") return CreateDatasetStage();
  if (type == "features") return CreateFeaturesStage();
  if (type == "matches") return CreateMatchesStage();
  if (type == "colmap_import") return CreateColmapImportStage();
  if (type == "bootstrap") return CreateBootstrapStage();
  if (type == "prior") return CreatePriorStage();
  if (type == "refine") return CreateRefineStage();
  if (type == "classical") return CreateClassicalStage();
  if (type == "evaluate") return CreateEvaluateStage();
  if (type == "export") return CreateExportStage();
  if (type == "splat") return CreateSplatStage();
  throw InputError(UnknownKeyMessage("the pipeline", type, StageTypes(), "stage"));
}

std::unique_ptr<Stage> ConfiguredStageOrNull(const std::string& type, const YAML::Node& options,
                                             const std::string& path) {
  try {
    std::unique_ptr<Stage> stage = CreateStage(type);
    stage->Configure(options, path);
    return stage;
  } catch (const std::exception&) {
    return nullptr;
  }
}

Provenance MakeProvenance(Stage& stage) {
  Provenance provenance;
  provenance.stage = stage.type();
  provenance.options = stage.OptionsJson();
  return provenance;
}

}  // namespace raytime
