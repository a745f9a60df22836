#!/usr/bin/env bash
# Configures and builds raytime (Release) into build/, or into $1 with extra CMake arguments;
# RAYTIME_TARGET limits the build to one target (e.g. unit_tests).
# Unity batches (CMAKE_UNITY_BUILD, 8 sources per compile): every source of a library parses and
# instantiates Eigen, nlohmann::json and Ceres again (~12 of a file's ~15 s), so a clean build
# takes 315 s instead of 540 (Release, 2 cores) and the sanitizer build 312 instead of 395. Names
# local to a source must therefore be unique in its library (DEVELOPERS.md). Incremental
# development builds leave it off (one changed file recompiles alone).
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${1:-build}"
shift || true
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=ON "$@" >/dev/null
ninja -C "$build_dir" ${RAYTIME_TARGET:-}
