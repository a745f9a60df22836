#include "core/content_hash.h"

#include <xxhash.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <vector>

#include "core/error.h"

namespace raytime {
namespace {

std::string Hex(XXH128_hash_t hash) {
  char buffer[33];
  std::snprintf(buffer, sizeof(buffer), "%016llx%016llx",
                static_cast<unsigned long long>(hash.high64),
                static_cast<unsigned long long>(hash.low64));
  return buffer;
}

}  // namespace

std::string HashBytes(const std::string& bytes) {
  return Hex(XXH3_128bits(bytes.data(), bytes.size()));
}

std::string HashFileContents(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInput(path, 0, "cannot read file");
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state(XXH3_createState(),
                                                                 &XXH3_freeState);
  XXH3_128bits_reset(state.get());
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    XXH3_128bits_update(state.get(), buffer.data(), static_cast<size_t>(in.gcount()));
  }
  return Hex(XXH3_128bits_digest(state.get()));
}

const std::string& ExecutableHash() {
  static const std::string hash = HashFileContents("/proc/self/exe");
  return hash;
}

}  // namespace raytime
