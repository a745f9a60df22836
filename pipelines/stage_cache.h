// Runs the stages of one pipeline in a work directory, each at most once: a stage whose content
// key (its id, options, the keys of the stages that made its inputs, the contents of external
// files, and this executable) is unchanged is skipped, and with a cache directory a stage another
// run computed is linked from the cache instead of recomputed (sweeps share one).
//
// WORKDIR/summary.json is written when the run starts (status "running"), after every stage, and
// at the end: "ok", "ok_with_warnings" (the stages' warnings collected in its top-level
// "warnings" list), "failed" (with the stage and the error) or, on SIGINT/SIGTERM,
// "interrupted" (with the stage). Temporary files a killed run left in the work directory are
// removed when the next run starts there.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "pipelines/pipeline_spec.h"

namespace raytime {

struct RunOptions {
  std::string workdir;    // overrides the pipeline's workdir when not empty
  bool force = false;     // rerun every stage even when unchanged
  std::string cache_dir;  // content-addressed stage outputs shared between runs ("" = none)
  int jobs = 0;           // concurrent sweep runs; 0 = number of cores
  // Where a sweep's runs execute: "local" (processes on this machine, up to `jobs` at once) or
  // "slurm" (job arrays on a Slurm cluster, pipelines/slurm_backend.h).
  std::string backend = "local";
  std::string partition;    // Slurm partition ("" = the cluster's default)
  bool slurm_wait = false;  // wait for the Slurm jobs and return the sweep's summary
};

// Runs `spec` (no sweep) in `workdir`; returns the summary written to WORKDIR/summary.json.
// Rethrows a stage's exception after writing the failed summary.
nlohmann::json RunStages(const PipelineSpec& spec, const std::string& workdir,
                         const RunOptions& options);

// Logs a stage summary's warnings, one line each (the log says each once, in words).
void LogWarnings(const std::string& stage_id, const nlohmann::json& stage_summary);

}  // namespace raytime
