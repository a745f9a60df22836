#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

// A fuzz target's entry point as linked into fuzz_replay (its LLVMFuzzerTestOneInput, renamed).
struct FuzzReplayTarget {
  const char* name;
  int (*test_one_input)(const uint8_t* data, size_t size);
};

// Every target of tests/fuzz/CMakeLists.txt; defined in the generated replay_targets.cc.
const std::vector<FuzzReplayTarget>& FuzzReplayTargets();
