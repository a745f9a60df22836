// libFuzzer target: pipeline files as `raytime run` reads them (pipelines/pipeline_spec.h):
// LoadPipeline (keys and value types), ApplyOverride as `--set` does, then ValidatePipeline (every
// stage's rules and relations) and, for a small sweep, ExpandSweep (each combination validated).
//
// Input: the YAML file, optionally followed by a line "#@set" and `--set` assignments
// STAGE.KEY=VALUE, one per line, applied in order until one is rejected.
//
// A pipeline that loads must survive its own round trip: sweep runs execute PipelineToYaml's
// output in a child process, so a spec that does not reload would fail there instead of here.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "core/error.h"
#include "pipelines/pipeline_spec.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  constexpr std::string_view kSet = "\n#@set\n";
  const size_t split = input.find(kSet);
  const std::string path = fuzz::ScratchPath("pipeline.yaml");
  fuzz::WriteFile(path, input.substr(0, split));
  PipelineSpec spec;
  try {
    spec = LoadPipeline(path);
  } catch (const InputError&) {
    return 0;
  }
  if (split != std::string_view::npos) {
    for (const std::string_view line : fuzz::SplitParts(input.substr(split + kSet.size()), "\n")) {
      try {
        ApplyOverride(&spec, std::string(line));
      } catch (const InputError&) {
        return 0;  // the command line stops here too; the spec is not used after a failed --set
      }
    }
  }
  // What RunPipeline checks before running: the values, or each sweep run's. A sweep's run count
  // is the product of its axes' lengths; beyond a few the expansion only costs time.
  try {
    ValidatePipeline(spec);
  } catch (const InputError&) {
  }
  size_t runs = 1;
  for (const auto& axis : spec.sweep) runs = std::min<size_t>(runs * axis.second.size(), 17);
  if (!spec.sweep.empty() && runs <= 16) {
    try {
      ExpandSweep(spec);
    } catch (const InputError&) {
    }
  }
  const std::string yaml = PipelineToYaml(spec);
  const std::string reload = fuzz::ScratchPath("run.yaml");
  fuzz::WriteFile(reload, yaml);
  try {
    LoadPipeline(reload);
  } catch (const InputError& e) {
    std::fprintf(stderr, "PipelineToYaml wrote a pipeline LoadPipeline rejects: %s\n%s\n", e.what(),
                 yaml.c_str());
    std::abort();
  }
  return 0;
}
