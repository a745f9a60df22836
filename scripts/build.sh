#!/usr/bin/env bash
# Configures and builds raytime (Release) into build/, or into $1 with extra CMake arguments;
# RAYTIME_TARGET limits the build to one target (e.g. unit_tests).
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir="${1:-build}"
shift || true
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
ninja -C "$build_dir" ${RAYTIME_TARGET:-}
