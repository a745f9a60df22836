// libFuzzer target: Strecha `.camera` files (formats/strecha.h, ReadStrechaCamera). The
// input is the file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/strecha.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  return fuzz::ReadAsFile(data, size, "0000.jpg.camera",
                          [](const std::string& path) { ReadStrechaCamera(path); });
}
