// libFuzzer target: the 3DGS trainers' metrics files (splat/splat_metrics.h,
// ReadTrainerMetrics). The input's first byte picks the trainer ('g' gsplat, 'i' inria, 'n'
// nerfstudio, any other byte by its value modulo 3); the rest is the file, written where that
// trainer puts it in its result folder (stats/val_step29999.json, results.json, eval.json).
#include <filesystem>
#include <string>
#include <string_view>

#include "core/error.h"
#include "splat/splat_metrics.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  if (size == 0) return 0;
  const char pick = static_cast<char>(data[0]);
  const std::string trainer = pick == 'g'   ? "gsplat"
                              : pick == 'i' ? "inria"
                              : pick == 'n' ? "nerfstudio"
                                            : kSplatTrainers[data[0] % 3];
  fuzz::ClearScratch();
  const std::string result = fuzz::ScratchPath("result");
  const std::string file = trainer == "gsplat"  ? result + "/stats/val_step29999.json"
                           : trainer == "inria" ? result + "/results.json"
                                                : result + "/eval.json";
  std::filesystem::create_directories(std::filesystem::path(file).parent_path());
  fuzz::WriteFile(file, std::string_view(reinterpret_cast<const char*>(data) + 1, size - 1));
  try {
    const TrainerMetrics metrics = ReadTrainerMetrics(trainer, result);
    std::string reason;
    TrainerHeldOutViews(trainer, result, metrics, &reason);
  } catch (const InputError&) {
  }
  return 0;
}
