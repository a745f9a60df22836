// YAML pipeline files: a dataset, a work directory and an ordered list of stages with their
// options, optionally a sweep that expands lists of values into runs (SPEC §6 campaigns).
//
//   name: demo
//   dataset: {format: strecha, root: data/sample/fountain-P11}
//   workdir: work/demo            # relative to the current directory; --workdir overrides
//   stages:
//     - prior: {level_deg: 4, seed: 0}
//     - evaluate: {poses: [prior]}
//   sweep:                        # optional: one run per combination
//     prior.level_deg: [0, 2, 4]
//     prior.seed: [0, 1, 2]
//
// The `dataset` stage always runs first from the `dataset` section. A stage type may appear more
// than once under distinct ids, `refine@plain` and `refine@gnc`; their pose sets are named
// `refined@plain` and `refined@gnc`.
//
// Options are checked in two steps so that the order of overrides never matters: loading and
// every override (--set, a sweep value) check keys and value types as they arrive; the values
// are validated once all of them are in place (ValidatePipeline, ExpandSweep).
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>
#include <utility>
#include <vector>

namespace raytime {

struct PipelineStageSpec {
  std::string id;      // "refine", or "refine@gnc" when a type appears more than once
  std::string type;    // "refine"
  YAML::Node options;  // mapping (possibly empty)
  int line = 0;        // where the entry is in the pipeline file
};

struct PipelineSpec {
  std::string path;  // the YAML file, for messages
  std::string name;
  std::string workdir;
  std::vector<PipelineStageSpec> stages;  // stages[0] is the dataset stage
  // Sweep axes in file order: "stage.key" and its values.
  std::vector<std::pair<std::string, std::vector<YAML::Node>>> sweep;
};

// Parses a pipeline file: unknown top-level keys, unknown stages, unknown option keys and wrong
// value types are InputErrors naming the file, the line and the nearest valid name. Values are
// not validated yet (ValidatePipeline).
PipelineSpec LoadPipeline(const std::string& path);

// Applies "stage.key=value" (value parsed as YAML, so lists work: prior.seed=[0,1]); checks the
// key and the value's type; "dataset.root=..." addresses the dataset section.
void ApplyOverride(PipelineSpec* spec, const std::string& assignment);

// Sets `stage.key` to `value`, naming `source` ("--set", "sweep") in errors; checks the key and
// the value's type only.
void SetStageOption(PipelineSpec* spec, const std::string& dotted_key, const YAML::Node& value,
                    const std::string& source);

// Validates every stage's options as a whole (rules and relations of the options structs):
// InputError naming the file and the stage's line.
void ValidatePipeline(const PipelineSpec& spec);

// One run of a sweep: its label ("level_deg=4,seed=0"), the swept values, the resolved spec.
struct SweepRun {
  std::string label;
  std::vector<std::pair<std::string, std::string>> swept;  // "prior.level_deg" -> "4"
  PipelineSpec spec;
};

// Every combination of the sweep's values, in file order, each validated as a whole (an invalid
// combination is an InputError naming the run).
std::vector<SweepRun> ExpandSweep(const PipelineSpec& spec);

// The pipeline as YAML (dataset, stages with their options; no workdir, no sweep): what a sweep
// run executes, written into its run folder.
std::string PipelineToYaml(const PipelineSpec& spec);

}  // namespace raytime
