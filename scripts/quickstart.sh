#!/usr/bin/env bash
# Quick start: install dependencies, build, and run the main job (configs/demo.yaml) on the
# sample scene shipped in data/sample. Results: work/demo/summary.json.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install_deps.sh
scripts/build.sh build
build/cli/raytime run configs/demo.yaml --workdir work/demo
echo "quickstart: done; see work/demo/summary.json"
