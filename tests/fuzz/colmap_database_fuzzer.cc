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
  return fuzz::ReadAsFile(data, size, "database.db",
                          [](const std::string& path) { ReadColmapDatabase(path); });
}
