// YAML pipelines: a dataset, a work directory and an ordered list of stages with their options,
// optionally a sweep that expands lists of values into runs (SPEC §6 campaigns).
//
//   name: demo
//   dataset: {format: strecha, root: data/sample/fountain-P11}
//   workdir: work/demo            # relative to the current directory; --workdir overrides
//   stages:
//     - prior: {level_deg: 4, seed: 0}
//     - evaluate: {poses: [prior]}
//   sweep:                        # optional: one run per combination, rows collected
//     prior.level_deg: [0, 2, 4]
//     prior.seed: [0, 1, 2]
//
// The `dataset` stage always runs first from the `dataset` section. A stage type may appear more
// than once under distinct ids, `refine@plain` and `refine@gnc`; their pose sets are named
// `refined@plain` and `refined@gnc`. Every stage writes WORKDIR/<id>.h5; a stage whose options
// and inputs (by content) are unchanged is skipped.
//
// Sweep runs execute as separate processes (HDF5 is not thread-safe), up to `jobs` at once, each
// in WORKDIR/runs/<label>/ with its resolved pipeline.yaml and run.log. They share a
// content-addressed cache of stage outputs (WORKDIR/cache), so stages that are identical across
// runs (a scene's features and matches) are computed once.
#pragma once

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>
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

// Parses and validates a pipeline file: unknown top-level keys, unknown stages, unknown option
// keys and wrong value types are InputErrors naming the file, the line and the nearest valid name.
PipelineSpec LoadPipeline(const std::string& path);

// Applies "stage.key=value" (value parsed as YAML, so lists work: prior.seed=[0,1]) and
// re-validates; "dataset.root=..." addresses the dataset section.
void ApplyOverride(PipelineSpec* spec, const std::string& assignment);

struct RunOptions {
  std::string workdir;    // overrides the pipeline's workdir when not empty
  bool force = false;     // rerun every stage even when unchanged
  std::string cache_dir;  // content-addressed stage outputs shared between runs ("" = none)
  int jobs = 0;           // concurrent sweep runs; 0 = number of cores
};

// The pipeline as YAML (dataset, stages with their options; no workdir, no sweep): what a sweep
// run executes, written into its run folder.
std::string PipelineToYaml(const PipelineSpec& spec);

// Runs the pipeline (or its sweep) and writes WORKDIR/summary.json, also when a stage fails
// (then with "status": "failed" and the error, and the exception is rethrown).
nlohmann::json RunPipeline(const PipelineSpec& spec, const RunOptions& options);

}  // namespace raytime
