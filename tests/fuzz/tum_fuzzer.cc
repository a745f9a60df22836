// libFuzzer target: TUM trajectories (formats/tum.h, ReadTumTrajectory).
//
// The input is the trajectory file; everything after a line "@@NAMES@@" is the optional names
// list, one name per line.
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"
#include "formats/tum.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  constexpr std::string_view kNames = "\n@@NAMES@@\n";
  const size_t split = input.find(kNames);
  std::vector<std::string> names;
  if (split != std::string_view::npos) {
    for (const std::string_view name :
         fuzz::SplitParts(input.substr(split + kNames.size()), "\n")) {
      names.emplace_back(name);
    }
  }
  const std::string path = fuzz::ScratchPath("trajectory.txt");
  fuzz::WriteFile(path, input.substr(0, split));
  try {
    ReadTumTrajectory(path, names);
  } catch (const InputError&) {
  }
  return 0;
}
