// Runs a fuzz target's entry point on files, without libFuzzer: every target is linked into the one
// `fuzz_replay` executable so that any compiler (CI's gcc with ASan/UBSan) replays the seed corpus
// and every crash reproducer as a regression test.
//
//   fuzz_replay tum tests/fuzz/corpus/tum [more files or folders ...]
//
// A folder stands for the files in it. A crash, sanitizer report or escaping exception fails the
// process, as it would under libFuzzer.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tests/fuzz/replay_targets.h"

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  const FuzzReplayTarget* target = nullptr;
  for (const FuzzReplayTarget& candidate : FuzzReplayTargets()) {
    if (argc > 1 && std::string(argv[1]) == candidate.name) target = &candidate;
  }
  if (target == nullptr) {
    std::fprintf(stderr, "usage: %s TARGET FILE_OR_FOLDER...  (TARGET one of:", argv[0]);
    for (const FuzzReplayTarget& candidate : FuzzReplayTargets()) {
      std::fprintf(stderr, " %s", candidate.name);
    }
    std::fprintf(stderr, ")\n");
    return 2;
  }
  std::vector<fs::path> files;
  for (int i = 2; i < argc; ++i) {
    if (fs::is_directory(argv[i])) {
      for (const auto& entry : fs::directory_iterator(argv[i])) {
        if (entry.is_regular_file()) files.push_back(entry.path());
      }
    } else if (fs::is_regular_file(argv[i])) {
      files.emplace_back(argv[i]);
    } else {
      std::fprintf(stderr, "%s: no such file or folder\n", argv[i]);
      return 2;
    }
  }
  if (files.empty()) {
    std::fprintf(stderr, "usage: %s %s FILE_OR_FOLDER...  (no inputs found)\n", argv[0],
                 target->name);
    return 2;
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& file : files) {
    std::ifstream in(file, std::ios::binary);
    if (!in) {
      std::fprintf(stderr, "%s: cannot open\n", file.c_str());
      return 2;
    }
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
    // Named before running, so the last line of a crash log is the input that caused it.
    std::fprintf(stderr, "%s\n", file.c_str());
    target->test_one_input(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  }
  std::printf("%zu inputs ran\n", files.size());
  return 0;
}
