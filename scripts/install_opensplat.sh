#!/usr/bin/env bash
# Builds and installs OpenSplat (github.com/pierotofy/OpenSplat, AGPL-3.0), the 3DGS trainer the
# splat stage runs with `trainer: opensplat` (issue 33), from Debian 12's packages: libtorch (CPU),
# nanoflann, cxxopts, glm. No source patch, no download besides the source itself.
#
#   scripts/install_opensplat.sh [SOURCE_DIR]
#
# SOURCE_DIR: an OpenSplat checkout to build (offline). Without it, the pinned commit below is
# cloned (needs the network). The binary goes to $PREFIX/bin/opensplat (PREFIX: /usr/local by
# default) and the commit it was built from to $PREFIX/share/opensplat/commit, which the splat
# stage records in its summary. Build jobs: JOBS (default: all cores).
#
# GPU build (a machine with an NVIDIA GPU; Debian's libtorch is CPU-only): CUDA's nvcc on PATH, a
# CUDA libtorch unpacked from pytorch.org (the cxx11-ABI zip), then
#   GPU_RUNTIME=CUDA LIBTORCH_DIR=/opt/libtorch scripts/install_opensplat.sh [SOURCE_DIR]
# The splat stage runs whichever `opensplat` is on PATH (or `splat.binary`), the same way.
set -euo pipefail
readonly PINNED_COMMIT=15b7e80016bb25107f07956b5682231f226f62b9  # 1.1.5, 2025-11-20
readonly REPOSITORY=https://github.com/pierotofy/OpenSplat
PREFIX=${PREFIX:-/usr/local}
GPU_RUNTIME=${GPU_RUNTIME:-CPU}
JOBS=${JOBS:-$(nproc)}
# Where CMake looks for Torch first: a libtorch of one's own (CUDA), then Debian's.
prefix_path=/usr/lib/x86_64-linux-gnu/cmake
if [ -n "${LIBTORCH_DIR:-}" ]; then
  [ -f "$LIBTORCH_DIR/share/cmake/Torch/TorchConfig.cmake" ] ||
    { echo "install_opensplat: LIBTORCH_DIR=$LIBTORCH_DIR holds no share/cmake/Torch/TorchConfig.cmake" >&2; exit 2; }
  prefix_path="$LIBTORCH_DIR;$prefix_path"
fi

packages=(build-essential cmake git libtorch-dev libnanoflann-dev libcxxopts-dev libglm-dev
          libopencv-dev)
"$(dirname "$0")/apt_install.sh" install_opensplat "${packages[@]}"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ $# -ge 1 ]; then
  source_dir=$(cd "$1" && pwd)
  [ -f "$source_dir/opensplat.cpp" ] || { echo "install_opensplat: $source_dir is no OpenSplat source (no opensplat.cpp)" >&2; exit 2; }
  commit=$(git -C "$source_dir" rev-parse HEAD 2>/dev/null || echo "unknown ($source_dir, not a git checkout)")
else
  source_dir="$work/OpenSplat"
  git clone -q "$REPOSITORY" "$source_dir"
  git -C "$source_dir" checkout -q "$PINNED_COMMIT"
  commit=$PINNED_COMMIT
fi
echo "install_opensplat: building $source_dir at $commit ($GPU_RUNTIME, $JOBS jobs)"
# FETCHCONTENT_*: the project fetches its dependencies unless told to find the installed ones.
cmake -S "$source_dir" -B "$work/build" -DGPU_RUNTIME="$GPU_RUNTIME" -DCMAKE_BUILD_TYPE=Release \
  -DFETCHCONTENT_FULLY_DISCONNECTED=ON -DFETCHCONTENT_TRY_FIND_PACKAGE_MODE=ALWAYS \
  -DCMAKE_PREFIX_PATH="$prefix_path" > "$work/cmake.log" 2>&1 ||
  { cat "$work/cmake.log" >&2; exit 1; }
cmake --build "$work/build" --target opensplat -j "$JOBS"
install -d "$PREFIX/bin" "$PREFIX/share/opensplat"
install -m 755 "$work/build/opensplat" "$PREFIX/bin/opensplat"
echo "$commit" > "$PREFIX/share/opensplat/commit"
echo "install_opensplat: $PREFIX/bin/opensplat ($("$PREFIX/bin/opensplat" --version 2>&1 | head -1)), commit $commit"
