// libFuzzer target: nerfstudio / instant-ngp transforms.json (formats/nerfstudio.h,
// ReadTransformsJson). The input is the file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/nerfstudio.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  const std::string path = fuzz::ScratchPath("transforms.json");
  fuzz::WriteFile(path, std::string_view(reinterpret_cast<const char*>(data), size));
  ImageSet images;
  PoseSet poses;
  try {
    ReadTransformsJson(path, &images, &poses);
  } catch (const InputError&) {
  }
  return 0;
}
