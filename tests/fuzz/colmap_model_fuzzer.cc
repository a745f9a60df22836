// libFuzzer target: COLMAP sparse models, text and binary (formats/colmap_model.h,
// ReadColmapModel, then FromColmapModel as every caller does).
//
// Input: one format byte ('b' binary, anything else text), then the contents of cameras,
// images and points3D separated by the line "@@FILE@@". A file whose part is absent (fewer
// separators) is not written, so missing files are covered too.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/colmap_model.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  if (size == 0) return 0;
  const bool binary = data[0] == 'b';
  const auto parts = fuzz::SplitParts(
      std::string_view(reinterpret_cast<const char*>(data) + 1, size - 1), "\n@@FILE@@\n");
  fuzz::ClearScratch();
  const char* const names[] = {"cameras", "images", "points3D"};
  for (size_t i = 0; i < 3 && i < parts.size(); ++i) {
    fuzz::WriteFile(fuzz::ScratchPath(std::string(names[i]) + (binary ? ".bin" : ".txt")),
                    parts[i]);
  }
  try {
    ImageSet images;
    PoseSet poses;
    FromColmapModel(ReadColmapModel(fuzz::ScratchDir()), &images, &poses);
  } catch (const InputError&) {
  }
  return 0;
}
