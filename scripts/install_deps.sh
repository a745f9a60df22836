#!/usr/bin/env bash
# Installs the Debian 12 packages raytime builds and runs with. Idempotent: skips apt when every
# package is already installed. --test adds what only the test suite needs: Debian's chromium, in
# which the run page is opened and clicked (tests/browser/check_run_page.py), and pytest for the
# Python module's tests (python/tests/).
set -euo pipefail
test_packages=()
if [ "${1:-}" = "--test" ]; then
  test_packages=(chromium python3-pytest)
fi
packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libceres-dev libsuitesparse-dev libtbb-dev libopencv-dev libopengv-dev
  libhdf5-dev libyaml-cpp-dev nlohmann-json3-dev libcli11-dev libspdlog-dev libxxhash-dev
  libsqlite3-dev libgtest-dev libgmock-dev
  colmap
  clang-14 libclang-rt-14-dev
  python3-matplotlib python3-numpy python3-dev pybind11-dev
  ${test_packages[@]+"${test_packages[@]}"}
)
exec "$(dirname "$0")/apt_install.sh" install_deps "${packages[@]}"
