// libFuzzer target: pipeline files (pipelines/pipeline.h: LoadPipeline, which also validates
// every stage's options, then ApplyOverride as `--set` does).
//
// Input: the YAML file, optionally followed by a line "#@set" and `--set` assignments
// STAGE.KEY=VALUE, one per line, applied in order until one is rejected.
//
// A pipeline that loads must survive its own round trip: sweep runs execute PipelineToYaml's
// output in a child process, so a spec that does not reload would fail there instead of here.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "core/error.h"
#include "pipelines/pipeline.h"
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
