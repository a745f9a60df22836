// Sweeps: every combination of a pipeline's sweep values run as a separate process (HDF5 is not
// thread-safe), up to `jobs` at once, each in WORKDIR/runs/<label>/ with its resolved
// pipeline.yaml and run.log. They share a content-addressed cache of stage outputs
// (WORKDIR/cache), so stages identical across runs (a scene's features and matches) are
// computed once. One row per run (report/sweep_row.h) in WORKDIR/sweep.json and sweep.csv,
// rewritten after every run so an interrupted sweep keeps its rows. WORKDIR/runs.json lists the
// runs (label, swept values, directory). options.backend "slurm" submits the runs to a Slurm
// cluster instead (pipelines/slurm_backend.h).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "pipelines/stage_cache.h"
#include "report/sweep_row.h"

namespace raytime {

nlohmann::json RunSweep(const PipelineSpec& spec, const std::string& workdir,
                        const RunOptions& options);

// Rebuilds WORKDIR/sweep.csv, sweep.json and summary.json from the runs listed in
// WORKDIR/runs.json (written by every sweep) and their summary.json files, without running
// anything: what the Slurm backend's last job does. A run without a finished summary is a failed
// row. Returns the sweep's summary (status "ok" or "failed", "failures").
nlohmann::json CollectSweep(const std::string& workdir);

// The sweep's exit: an InputError saying how many of its runs failed, when any did.
void ThrowIfRunsFailed(int failures, size_t num_runs, const std::string& workdir);

// A run's row from its summary.json (a missing or unreadable one makes a failed row).
SweepRow SweepRowFromRun(const std::string& label,
                         const std::vector<std::pair<std::string, std::string>>& swept,
                         const std::string& run_dir);

}  // namespace raytime
