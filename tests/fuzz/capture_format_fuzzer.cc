// libFuzzer entry point of one capture_<name> target: the body of capture_fuzzer.cc for the
// dataset.format RAYTIME_CAPTURE_FORMAT (this small file is what tests/fuzz/CMakeLists.txt
// compiles once per format).
#include "tests/fuzz/capture_fuzz.h"

#ifndef RAYTIME_CAPTURE_FORMAT
#error "compile with -DRAYTIME_CAPTURE_FORMAT=\"<dataset.format>\""
#endif

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return raytime::fuzz::FuzzCapture(RAYTIME_CAPTURE_FORMAT, data, size);
}
