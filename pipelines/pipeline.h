// Running a pipeline: one run of its stages in a work directory (pipelines/stage_cache.h), or,
// for a pipeline with a sweep section, one process per combination (pipelines/sweep.h). The
// pipeline file and its overrides: pipelines/pipeline_spec.h.
#pragma once

#include <nlohmann/json.hpp>

#include "pipelines/pipeline_spec.h"
#include "pipelines/stage_cache.h"

namespace raytime {

// Validates the options once all overrides are in place (every sweep combination, for a sweep),
// then runs the pipeline or its sweep. Writes WORKDIR/summary.json, also when a stage fails (then
// with "status": "failed" and the error, and the exception is rethrown).
nlohmann::json RunPipeline(const PipelineSpec& spec, const RunOptions& options);

}  // namespace raytime
