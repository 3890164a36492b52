#!/usr/bin/env bash
# Installs what is missing, builds Specula three times and runs every test through ctest on each:
#   1. the `ci` preset: optimised, warnings as errors, benchmarks built and smoke-run;
#   2. the `ci-native` preset: the same without the optional backends (SPECULA_WITH_EMBREE=OFF,
#      SPECULA_WITH_VULKAN=OFF), so the engine builds, renders and passes its tests on the native
#      CPU backend alone (the Vulkan tests, which run on Specula's own structures whatever the CPU
#      backends, run in the other two presets, and so do the tests of the modules no backend
#      option touches: core, ecs, geometry, image, scene; SPECULA_TEST_TRACER_FREE_MODULES);
#   3. the `asan` preset: Clang 15, AddressSanitizer and UBSan, assertions on, so the death tests
#      compiled out of optimised builds run, and memory errors and leaks fail the run; then each
#      libFuzzer harness of tests/fuzz/ (built in the same preset) fuzzes for
#      SPECULA_FUZZ_SECONDS (default 30) from its seed corpus with a fixed seed, and any finding
#      fails the run (scripts/fuzz.sh, docs/fuzzing.md; SPECULA_FUZZ_SECONDS=0 skips it).
# Every preset's ctest also replays the fuzzers' corpora and regression inputs (label "fuzz").
# SPECULA_TEST_PRESETS="ci" (or any list of them) runs those only.
# CI's time (keep it under 45 min on 2 cores): the ci presets compile with -g1 (line tables and
# function names, enough for backtraces; full -g made the test files ~70% slower to compile) and all
# three link with lld; the asan preset's brute-force tests trace a quarter of the rays, and it
# skips the install test (label "install": packaging, checked by the other two presets). Measured
# on a clean clone here: 43.8 min with 30 s of fuzzing (2026-11-24); 26.2 min on 2026-11-25 (same
# tree size, a faster machine that day: the time varies with the machine lent); CI's own run of
# 2026-11-27 took 47.6 min, after which ci-native stopped building the tracer-free modules' tests
# and the subcommands are compiled once (a library) instead of once more per test using them:
# 41.9 and 44.4 min on two clean clones here afterwards (43.5 min for the tree before); CI's own
# run then took 43.6 min. On 2026-11-27 evening the program stopped creating a Vulkan instance at
# every start (the CLI tests start it hundreds of times): 41.5 min on a clean clone here.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
jobs=$(nproc 2>/dev/null || echo 2)
for preset in ${SPECULA_TEST_PRESETS:-ci ci-native asan}; do
  echo "== $preset: configure, build, test"
  cmake --preset "$preset"
  cmake --build --preset "$preset" -j "$jobs"
  ctest --preset "$preset" -j "$jobs"
  if [ "$preset" = asan ] && [ "${SPECULA_FUZZ_SECONDS:-30}" != 0 ]; then
    echo "== asan: timed fuzzing"
    bash scripts/fuzz.sh --seed 1 all "${SPECULA_FUZZ_SECONDS:-30}"
  fi
done
