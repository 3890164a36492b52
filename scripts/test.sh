#!/usr/bin/env bash
# Installs what is missing, builds Specula (the `ci` preset: optimised, warnings as errors) and
# runs every test through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
jobs=$(nproc 2>/dev/null || echo 2)
cmake --preset ci
cmake --build --preset ci -j "$jobs"
ctest --preset ci -j "$jobs"
