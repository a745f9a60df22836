// The Slurm backend of sweeps (issue 14): a sweep's runs submitted as job arrays to a Slurm
// cluster, its work directory and stage cache on a path every node sees. Each array task is one
// run, exactly as the local backend starts it (`raytime run RUN_DIR/pipeline.yaml --workdir
// RUN_DIR --cache-dir CACHE`, output to RUN_DIR/run.log). Runs that share a scene's expensive
// stages (features, matches: the same dataset.* values) are split so those stages are computed
// once: a leader array (the first run of each scene) and a follower array that starts after it
// (dependency afterany; a follower whose leader failed recomputes the stages itself). A last job
// collects the rows into sweep.csv, sweep.json and summary.json and writes the campaign report
// (`raytime report --sweep WORKDIR --collect`). A resubmission submits only the runs without a
// successful summary.json (all with --force).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pipelines/pipeline_spec.h"
#include "pipelines/stage_cache.h"

namespace raytime {

// Submits `runs` (their directories `run_dirs` already hold pipeline.yaml) and returns the
// submission ({"backend": "slurm", "jobs": {...}, "submitted": N, "skipped": M}); with
// options.slurm_wait, waits for the collect job and returns the sweep's summary instead. The
// submission scripts and Slurm's own output go to WORKDIR/slurm/. Throws InputError when sbatch is
// missing or refuses a job (its message included).
nlohmann::json SubmitSweepToSlurm(const PipelineSpec& spec, const std::string& workdir,
                                  const std::vector<SweepRun>& runs,
                                  const std::vector<std::string>& run_dirs,
                                  const std::string& cache_dir, const RunOptions& options);

}  // namespace raytime
