// The capture readers' fuzz target body (capture_fuzzer.cc), run for one dataset.format; each
// capture_<name> target's entry point (capture_format_fuzzer.cc) calls it with its format.
#pragma once

#include <cstddef>
#include <cstdint>

namespace raytime::fuzz {

// Writes the input's folder and reads it as `format` (capture_fuzzer.cc says how); returns 0.
int FuzzCapture(const char* format, const uint8_t* data, size_t size);

}  // namespace raytime::fuzz
