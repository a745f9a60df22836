// libFuzzer target: NumPy .npz archives (formats/npz.h, ReadNpz), the one binary format of the
// capture readers (MobileBrick's cameras_arkit.npz; capture_mobilebrick reaches it only behind a
// valid sequence folder).
//
// The input is the .npz file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/npz.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  return fuzz::ReadAsFile(data, size, "cameras.npz",
                          [](const std::string& path) { ReadNpz(path); });
}
