// Tests on ../shared/data (the Strecha scenes and the phone captures): skipped in a clone without
// it, failed where RAYTIME_REQUIRE_SHARED_DATA is set (CI, scripts/test.sh), where a skip would
// pass a test that checked nothing.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

// Use as the test body's first statement: REQUIRE_SHARED_DATA(path);
#define REQUIRE_SHARED_DATA(path)                                                  \
  do {                                                                             \
    if (!std::filesystem::exists(path)) {                                          \
      if (std::getenv("RAYTIME_REQUIRE_SHARED_DATA") != nullptr) {                 \
        FAIL() << "shared data not found (RAYTIME_REQUIRE_SHARED_DATA): " << path; \
      }                                                                            \
      GTEST_SKIP() << "shared data not found: " << path;                           \
    }                                                                              \
  } while (false)
