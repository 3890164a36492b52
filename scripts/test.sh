#!/usr/bin/env bash
# Installs what is missing, builds Specula twice and runs every test through ctest on each build:
#   1. the `ci` preset: optimised, warnings as errors, benchmarks built and smoke-run;
#   2. the `asan` preset: debug with AddressSanitizer and UBSan, so assertions and the death
#      tests compiled out of optimised builds run, and memory errors and leaks fail the run.
# SPECULA_TEST_PRESETS="ci" (or "asan") runs one of them only.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
jobs=$(nproc 2>/dev/null || echo 2)
for preset in ${SPECULA_TEST_PRESETS:-ci asan}; do
  echo "== $preset: configure, build, test"
  cmake --preset "$preset"
  cmake --build --preset "$preset" -j "$jobs"
  ctest --preset "$preset" -j "$jobs"
done
