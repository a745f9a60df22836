// A pipeline stage: named options (YAML keys = field names), the artifacts it reads and writes,
// and one Run(). Stages meet only here, through HDF5 files in the work directory.
#pragma once

#include <yaml-cpp/yaml.h>
#include <CLI/CLI.hpp>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/options.h"

namespace raytime {

// Artifact names: what a stage reads and writes. Each lives in the HDF5 file of the stage that
// wrote it last.
inline constexpr const char* kArtifactImages = "images";
inline std::string PoseArtifact(const std::string& pose_set) { return "poses/" + pose_set; }

struct StageContext {
  // The stage's id in the pipeline: its type, or "type@name" when a pipeline runs one stage type
  // more than once (two refine arms, say). Pose sets the stage writes carry the same suffix.
  std::string stage_id;
  std::string workdir;
  // Artifact -> HDF5 file holding it (the latest writer's file).
  std::map<std::string, std::string> artifacts;
  // The HDF5 file this stage writes (WORKDIR/<stage>.h5); other outputs go below workdir.
  std::string output_path;

  // File holding `artifact`; InputError naming the artifact and the stage that should make it.
  const std::string& Require(const std::string& artifact) const;
  // "refined" for stage "refine", "refined@gnc" for stage "refine@gnc".
  std::string OutputPoseSetName(const std::string& base) const;
};

// The type of a stage id: "refine@gnc" -> "refine".
std::string StageTypeOfId(const std::string& stage_id);

class Stage {
 public:
  virtual ~Stage() = default;
  virtual std::string type() const = 0;
  virtual std::string description() const = 0;

  // Option handling, generated from the options struct (see StageWithOptions).
  virtual void Configure(const YAML::Node& options, const std::string& path) = 0;
  virtual nlohmann::json OptionsJson() = 0;
  virtual std::vector<std::string> OptionKeys() = 0;
  virtual void BindCli(CLI::App* app) = 0;

  // Artifacts read. What a stage wrote is read back from its HDF5 file by the runner.
  virtual std::vector<std::string> Inputs() const = 0;
  // Files or folders below workdir written besides output_path (checked before skipping).
  virtual std::vector<std::string> ExtraOutputs() const { return {}; }
  // Files outside the work directory whose contents the result depends on (content-hashed).
  virtual std::vector<std::string> ExternalFiles() const { return {}; }

  // Runs the stage and returns its summary (timings, counts, metrics, guardrail verdicts).
  virtual nlohmann::json Run(const StageContext& context) = 0;
};

namespace stage_detail {
struct CliBinder {
  CLI::App* app;
  template <typename T>
  void operator()(const char* key, T& field) {
    auto* option = app->add_option(std::string("--") + key, field);
    option->capture_default_str();
  }
};
}  // namespace stage_detail

// Implements the option plumbing of Stage from an options struct with VisitFields.
template <typename Options>
class StageWithOptions : public Stage {
 public:
  void Configure(const YAML::Node& node, const std::string& path) override {
    ApplyYaml(node, options_, path, "stage '" + type() + "'");
    Validate();
  }
  nlohmann::json OptionsJson() override { return OptionsToJson(options_); }
  std::vector<std::string> OptionKeys() override { return raytime::OptionKeys(options_); }
  void BindCli(CLI::App* app) override {
    stage_detail::CliBinder binder{app};
    options_.VisitFields(binder);
  }
  // Checks option values after Configure (and after CLI parsing); throws InputError.
  virtual void Validate() {}

  const Options& options() const { return options_; }

 protected:
  Options options_;
};

// All stage types, in pipeline order.
std::vector<std::string> StageTypes();
// A fresh stage of a type; InputError with the nearest valid type otherwise.
std::unique_ptr<Stage> CreateStage(const std::string& type);

}  // namespace raytime
