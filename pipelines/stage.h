// A pipeline stage: named options (YAML keys = field names), the artifacts it reads and writes,
// and one Run(). Stages meet only here, through HDF5 files in the work directory.
#pragma once

#include <yaml-cpp/yaml.h>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/artifacts.h"
#include "core/options.h"

// CLI11 is header-only and heavy: only stage.cc and the CLI need its definitions.
namespace CLI {
class App;
}

namespace raytime {

class Hdf5Reader;

struct StageContext {
  // The stage's id in the pipeline: its type, or "type@name" when a pipeline runs one stage type
  // more than once (two refine arms, say). Pose sets the stage writes carry the same suffix.
  std::string stage_id;
  std::string workdir;
  // Artifact -> HDF5 file holding it (the latest writer's file).
  std::map<std::string, std::string> artifacts;
  // The HDF5 file this stage writes (WORKDIR/<stage>.h5); other outputs go below workdir.
  std::string output_path;
  // `raytime run --force`: redo also what a stage would reuse from its own earlier results (the
  // splat stage's finished trainings).
  bool force = false;
  // The output this stage wrote at its previous run in this work directory, when its inputs or
  // options have changed since (else the stage is skipped) and the file is still the one it wrote
  // (the checksum in its record); "" when there is none or with --force. A stage may reuse
  // results in it item by item under content keys (issue 34: features of unchanged images,
  // matches of unchanged pairs, the previous solution as a warm start). It stays in place until
  // this run's output replaces it.
  std::string previous_output;

  // File holding `artifact`; MissingArtifactError naming the artifact and those there are.
  const std::string& Require(const std::string& artifact) const;
  // Runs `read` on previous_output, when there is one; false when there is none or `read` throws
  // (a warning names the file, the error and `fallback`, what the stage does instead).
  bool ReadPreviousOutput(const std::function<void(const Hdf5Reader&)>& read,
                          const std::string& fallback) const;
  // "refined" for stage "refine", "refined@gnc" for stage "refine@gnc".
  std::string OutputPoseSetName(const std::string& base) const;
};

// A stage needs an artifact no earlier stage wrote: the pipeline needs fixing, so the run stops
// even where the stage's own failures would not stop it (Stage::FailureStopsRun).
class MissingArtifactError : public InputError {
 public:
  using InputError::InputError;
};

// The type of a stage id: "refine@gnc" -> "refine".
std::string StageTypeOfId(const std::string& stage_id);

class Stage {
 public:
  virtual ~Stage() = default;
  virtual std::string type() const = 0;
  virtual std::string description() const = 0;

  // Option handling, generated from the options struct (see StageWithOptions).
  // Sets every option: the defaults (and a preset's values, where the stage has presets), then
  // the keys given in `options` (explicit keys always win), then validates them all at once.
  // InputError naming `path` on an unknown key, a wrong type or an invalid value.
  virtual void Configure(const YAML::Node& options, const std::string& path) = 0;
  // Checks the keys and value types of `options` without validating values: a pipeline file's
  // values may still be overridden, and are validated once all overrides are in place.
  virtual void CheckKeysAndTypes(const YAML::Node& options, const std::string& path) = 0;
  // The same, and each given value's own rules (a range, a list of names): for an override (a
  // --set, a sweep value), which nothing replaces, so that a bad one is blamed on itself at once.
  // Relations between options are still validated once all of them are in place.
  virtual void CheckOverride(const YAML::Node& options, const std::string& path) = 0;
  virtual nlohmann::json OptionsJson() = 0;
  // Every option's key, default, description and rules, in declaration order.
  virtual std::vector<OptionDoc> OptionDocs() = 0;
  // The deprecated keys the options still accept (core/options.h OptionAlias).
  virtual std::vector<OptionAlias> DeprecatedAliases() = 0;
  std::vector<std::string> OptionKeys();
  // `raytime STAGE`: one --KEY per option with its description (and one per deprecated key, left
  // out of --help); CliOptions() returns the flags given on the command line as the YAML mapping
  // for Configure.
  void BindCli(CLI::App* app);
  YAML::Node CliOptions() const;

  // Artifacts read. What a stage wrote is read back from its HDF5 file by the runner.
  virtual std::vector<std::string> Inputs() const = 0;
  // Files or folders below workdir written besides output_path (checked before skipping).
  virtual std::vector<std::string> ExtraOutputs() const { return {}; }
  // Files outside the work directory whose contents the result depends on (content-hashed).
  virtual std::vector<std::string> ExternalFiles() const { return {}; }
  // Folders outside the work directory this stage reads whole (the dataset's image folder): the
  // work directory may be none of them nor lie inside one, or raytime would read back its own
  // files as the user's (RunPipeline refuses it before writing anything).
  virtual std::vector<std::string> InputFolders() const { return {}; }
  // Refuses (InputError naming the image and what to do) image names this stage could not write
  // with its options: called before any work, once the dataset stage has listed the images, so
  // that a name an export cannot hold is not found after the whole solve.
  virtual void CheckImageNames(const std::vector<std::string>& names) const {}
  // Whether the result an earlier run left in `context.workdir` is complete. A stage that returns
  // partial failures as warnings (a trainer that failed for one pose set) says false so that a
  // rerun with unchanged inputs retries them instead of skipping the stage.
  virtual bool Complete(const StageContext& context) const { return true; }
  // Whether sweep runs may share this stage's result through the cache, which holds only its HDF5
  // file: not when it writes files besides it.
  virtual bool Cacheable() const { return ExtraOutputs().empty(); }
  // Whether the run stops when this stage fails. A measurement (evaluate) does not: its failure
  // is a stage_failed warning and the stages after it (the export of the user's poses) go on.
  // An input that no earlier stage wrote (MissingArtifactError) stops the run whatever this says.
  virtual bool FailureStopsRun() const { return true; }

  // Runs the stage and returns its summary (timings, counts, metrics, guardrail verdicts, and
  // "warnings": an array of core/warnings.h objects the pipeline collects into summary.json).
  virtual nlohmann::json Run(const StageContext& context) = 0;

 private:
  std::vector<OptionDoc> cli_docs_;                             // of the bound options
  std::map<std::string, std::vector<std::string>> cli_values_;  // --KEY values given
};

// Implements the option plumbing of Stage from an options struct with VisitFields.
template <typename Options>
class StageWithOptions : public Stage {
 public:
  void Configure(const YAML::Node& node, const std::string& path) override {
    options_ = Options();
    ApplyPreset(node, path);
    ApplyYaml(node, options_, path, What());
    ValidateOptions(options_, What());
  }
  void CheckKeysAndTypes(const YAML::Node& node, const std::string& path) override {
    Options probe;
    ApplyYaml(node, probe, path, What());
  }
  void CheckOverride(const YAML::Node& node, const std::string& path) override {
    Options probe;
    ApplyYaml(node, probe, path, What());
    ValidateGivenFields(node, probe, path, What());
  }
  nlohmann::json OptionsJson() override { return OptionsToJson(options_); }
  std::vector<OptionDoc> OptionDocs() override {
    Options defaults;
    return raytime::OptionDocs(defaults);
  }
  std::vector<OptionAlias> DeprecatedAliases() override {
    return raytime::DeprecatedAliases<Options>();
  }

  const Options& options() const { return options_; }

 protected:
  // Stages with named presets set the preset's values here, before the explicit keys.
  virtual void ApplyPreset(const YAML::Node& node, const std::string& path) {}
  std::string What() const { return "stage '" + type() + "'"; }

  Options options_;
};

// All stage types, in pipeline order.
std::vector<std::string> StageTypes();
// A fresh stage of a type; InputError with the nearest valid type otherwise.
std::unique_ptr<Stage> CreateStage(const std::string& type);
// A stage of `type` configured with `options` (from `path`), or null when it does not configure:
// for the runner's passes over a pipeline that need what a stage would do (its outputs, the
// folders it reads) and leave the error to the stage's own turn.
std::unique_ptr<Stage> ConfiguredStageOrNull(const std::string& type, const YAML::Node& options,
                                             const std::string& path);

}  // namespace raytime
