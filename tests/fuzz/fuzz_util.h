// Helpers shared by the libFuzzer targets (tests/fuzz/*_fuzzer.cc): a scratch directory for
// parsers that take paths, splitting one input into several files, and a byte reader for the
// structure-aware targets.
#pragma once

#include <stdlib.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/error.h"

namespace raytime::fuzz {

// A directory owned by this process, removed at exit. Under $TMPDIR when set (scripts/fuzz.sh
// points it at a folder it deletes afterwards, which also catches a crashed process's leftovers),
// else /dev/shm: a fuzzer rewrites its input file thousands of times a second, which a disk
// should not see.
class Scratch {
 public:
  Scratch() {
    namespace fs = std::filesystem;
    const char* tmpdir = std::getenv("TMPDIR");
    const fs::path base = tmpdir != nullptr && *tmpdir != '\0' ? fs::path(tmpdir)
                          : fs::is_directory("/dev/shm")       ? fs::path("/dev/shm")
                                                               : fs::temp_directory_path();
    path_ = (base / "raytime_fuzz_XXXXXX").string();
    if (mkdtemp(path_.data()) == nullptr) {
      std::perror(("mkdtemp " + path_).c_str());
      std::abort();
    }
  }
  ~Scratch() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

inline const std::string& ScratchDir() {
  static const Scratch scratch;
  return scratch.path();
}

// A path inside ScratchDir().
inline std::string ScratchPath(const std::string& name) { return ScratchDir() + "/" + name; }

// Empties ScratchDir() so that files of the previous input do not leak into this one.
inline void ClearScratch() {
  std::error_code ignored;
  for (const auto& entry : std::filesystem::directory_iterator(ScratchDir(), ignored)) {
    std::filesystem::remove_all(entry.path(), ignored);
  }
}

inline void WriteFile(const std::string& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    std::perror(("cannot write " + path).c_str());
    std::abort();
  }
}

// The parts of `bytes` between occurrences of `separator`. A multi-byte separator keeps each
// part mutable on its own: libFuzzer's inserts and deletes inside one part leave the others as
// they were, which a length prefix would not.
inline std::vector<std::string_view> SplitParts(std::string_view bytes,
                                                std::string_view separator) {
  std::vector<std::string_view> parts;
  size_t start = 0;
  while (true) {
    const size_t end = bytes.find(separator, start);
    if (end == std::string_view::npos) break;
    parts.push_back(bytes.substr(start, end - start));
    start = end + separator.size();
  }
  parts.push_back(bytes.substr(start));
  return parts;
}

// Consumes a fuzz input front to back for the structure-aware targets; an exhausted input reads
// as zeros, so every input decodes to something.
class ByteReader {
 public:
  ByteReader(const uint8_t* data, size_t size) : data_(data), size_(size) {}

  bool empty() const { return pos_ >= size_; }
  uint8_t Byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  bool Bool() { return Byte() & 1; }
  // Uniform-ish in [0, n) for small n.
  unsigned Pick(unsigned n) { return n == 0 ? 0 : Byte() % n; }
  template <typename T>
  T Value() {
    T value{};
    uint8_t bytes[sizeof(T)] = {};
    for (uint8_t& b : bytes) b = Byte();
    std::memcpy(&value, bytes, sizeof(T));
    return value;
  }
  // Up to `max` raw bytes, the count given by the first byte.
  std::string String(size_t max = 255) {
    const size_t n = std::min<size_t>(Byte(), max);
    std::string s;
    for (size_t i = 0; i < n && !empty(); ++i) s.push_back(static_cast<char>(Byte()));
    return s;
  }
  // `n` raw bytes, zero-padded when the input runs out.
  std::string Bytes(size_t n) {
    std::string s(n, '\0');
    for (char& c : s) c = static_cast<char>(Byte());
    return s;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

// The target of a parser that takes a path: writes the input as `name` in ScratchDir() and calls
// `read(path)`. An InputError is the parser's answer to bad bytes; anything else escapes for the
// fuzzer to report.
template <typename Read>
int ReadAsFile(const uint8_t* data, size_t size, const std::string& name, Read&& read) {
  const std::string path = ScratchPath(name);
  WriteFile(path, std::string_view(reinterpret_cast<const char*>(data), size));
  try {
    read(path);
  } catch (const InputError&) {
  }
  return 0;
}

}  // namespace raytime::fuzz
