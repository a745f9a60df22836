// libFuzzer target: nerfstudio / instant-ngp transforms.json (formats/nerfstudio.h,
// ReadTransformsJson). The input is the file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/nerfstudio.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  return fuzz::ReadAsFile(data, size, "transforms.json", [](const std::string& path) {
    ImageSet images;
    PoseSet poses;
    ReadTransformsJson(path, &images, &poses);
  });
}
