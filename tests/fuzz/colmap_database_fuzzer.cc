// libFuzzer target: COLMAP database.db files (formats/colmap_database.h,
// ReadColmapDatabase), byte-level. The input is the SQLite file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "formats/colmap_database.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  // A database whose header asks for WAL mode makes SQLite look for -wal and -shm siblings.
  fuzz::ClearScratch();
  const std::string path = fuzz::ScratchPath("database.db");
  fuzz::WriteFile(path, std::string_view(reinterpret_cast<const char*>(data), size));
  try {
    ReadColmapDatabase(path);
  } catch (const InputError&) {
  }
  return 0;
}
