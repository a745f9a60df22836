#!/usr/bin/env bash
# Test suite: install dependencies (with chromium, for the run page's browser test); a Release build
# runs the tests that drive the binary, COLMAP, headless Chromium, a one-node Slurm cluster and the
# Python module with Debian's python3 (labels integration, colmap, slurm, python); the unit tests
# and fuzz corpus replays are built and run once, with AddressSanitizer + UndefinedBehaviorSanitizer
# (building them at -O3 as well was a sixth of CI).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)
scripts/install_deps.sh --test
# With the benchmarks, compiled but not run (timing is no test): left out, refine_bench stopped
# compiling unnoticed (fixed in fedb421).
scripts/build.sh build -DRAYTIME_BUILD_UNIT_TESTS=OFF -DRAYTIME_BUILD_BENCH=ON
echo "test.sh: release build done at ${SECONDS} s"
# The Slurm backend's test (label slurm) on a one-node cluster on this machine; it must run here
# (RAYTIME_REQUIRE_SLURM), where elsewhere it is skipped without a cluster. The tests on
# ../shared/data fail here without it (RAYTIME_REQUIRE_SHARED_DATA), and skip in a lone clone.
scripts/slurm_local.sh start
(cd build && RAYTIME_REQUIRE_SLURM=1 RAYTIME_REQUIRE_BROWSER=1 RAYTIME_REQUIRE_SHARED_DATA=1 \
  ctest --output-on-failure -j "$jobs")
echo "test.sh: tests done at ${SECONDS} s"
# clang: compiles the instrumented code about twice as fast as gcc, and its UBSan checks pointer
# overflow, which gcc's lacks (scripts/fuzz.sh uses it too). -g1: line tables only, enough for the
# sanitizers' file:line stack traces.
RAYTIME_TARGET=unit_tests scripts/build.sh build-asan -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_CXX_FLAGS_DEBUG=-g1 \
  -DRAYTIME_SANITIZE=ON -DRAYTIME_PRECOMPILED_HEADERS=ON
echo "test.sh: sanitizer build done at ${SECONDS} s"
(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  RAYTIME_REQUIRE_SHARED_DATA=1 ctest --output-on-failure -j "$jobs" -L unit)
echo "test.sh: sanitizer tests done at ${SECONDS} s"
