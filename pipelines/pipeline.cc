#include "pipelines/pipeline.h"

#include "core/error.h"
#include "pipelines/sweep.h"

namespace raytime {

nlohmann::json RunPipeline(const PipelineSpec& spec, const RunOptions& options) {
  const std::string workdir = !options.workdir.empty() ? options.workdir : spec.workdir;
  if (workdir.empty()) {
    throw InputError(spec.path + ": no work directory (set 'workdir' or pass --workdir)");
  }
  if (!spec.sweep.empty()) return RunSweep(spec, workdir, options);
  ValidatePipeline(spec);
  return RunStages(spec, workdir, options);
}

}  // namespace raytime
