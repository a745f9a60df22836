#!/usr/bin/env bash
# Test suite: install dependencies, build, run every test, then rebuild the unit tests with
# AddressSanitizer + UndefinedBehaviorSanitizer and run them again.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)
scripts/install_deps.sh
scripts/build.sh build
(cd build && ctest --output-on-failure -j "$jobs")
RAYTIME_TARGET=unit_tests scripts/build.sh build-asan -DCMAKE_BUILD_TYPE=Debug -DRAYTIME_SANITIZE=ON
(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --output-on-failure -j "$jobs" -L unit)
