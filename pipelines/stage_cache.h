// Runs the stages of one pipeline in a work directory, each at most once: a stage whose content
// key (its id, options, the keys of the stages that made its inputs, the contents of external
// files, and this executable) is unchanged is skipped, and with a cache directory a stage another
// run computed is linked from the cache instead of recomputed (sweeps share one).
//
// WORKDIR/summary.json is written when the run starts (status "running"), after every stage, and
// at the end: "ok", "ok_with_warnings" (the stages' warnings collected in its top-level
// "warnings" list), "failed" (with the stage and the error) or, on SIGINT/SIGTERM,
// "interrupted" (with the stage); a process that crashed is recorded "crashed" by the command's
// supervising parent (RecordCrashedRun). A failure's "cause" says its class (core/
// resource_failure.h: input, memory, threads, open_files, disk_space, error). Temporary files a
// killed run left in the work directory are removed when the next run starts there.
#pragma once

#include <filesystem>
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

// Finishes the record of a run whose process `pid` crashed (killed by `signal`, or 0: it ended
// without recording how) while running `spec` in `workdir` since `run_start` (on the file
// system's clock): status "crashed", `error`, `cause`,
// the outputs of the stages it had not completed moved to stale/ as a failure moves them, and the
// run page. False, touching nothing, when summary.json is not that process's running record.
bool RecordCrashedRun(const PipelineSpec& spec, const std::string& workdir, int pid,
                      std::filesystem::file_time_type run_start, const std::string& error,
                      const std::string& cause, int signal);

// Logs a stage summary's warnings, one line each (the log says each once, in words).
void LogWarnings(const std::string& stage_id, const nlohmann::json& stage_summary);

}  // namespace raytime
