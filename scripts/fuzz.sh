#!/usr/bin/env bash
# Runs Specula's libFuzzer harnesses (tests/fuzz/, docs/fuzzing.md) for a bounded time each.
#
#   scripts/fuzz.sh [--merge] [--seed N] [READER|all] [SECONDS]
#
# READER is one of: json gltf glb aff obj ply off stl png exr render (default: all of them);
# SECONDS is each fuzzer's budget (default 300). Builds what is missing in the `asan` preset
# (Clang 15, ASan + UBSan, libFuzzer) first. Each fuzzer starts from its seed corpus
# (tests/fuzz/corpus/READER/) and the regressions (tests/data/fuzz-regressions/READER/) with its
# dictionary; the inputs it finds go to a scratch folder, so the repository is left as it is unless
# --merge is given, which then adds to tests/fuzz/corpus/READER/ the inputs that bring new coverage
# (review their sizes before committing). --seed fixes libFuzzer's random seed (CI uses 1; default:
# a random one). Findings (crash, sanitizer report, leak, timeout, out of memory) are saved under
# build/asan/fuzz-findings/READER/; the script goes on with the other readers and exits 1 if any
# fuzzer found something, naming the reproducers. Replay one with
#   build/asan/tests/fuzz/fuzz_READER FILE
# Environment: SPECULA_FUZZ_TIMEOUT (seconds one input may take, default 10),
# SPECULA_FUZZ_RSS_MB (memory limit, default 2048), SPECULA_FUZZ_MALLOC_MB (largest single
# allocation, default 1024: a small input asking for more is a finding even when the block is never
# touched), SPECULA_FUZZ_FLAGS (more libFuzzer flags), SPECULA_FUZZ_JOBS (fuzzers run side by side,
# default one per core).
set -euo pipefail
cd "$(dirname "$0")/.."

all_readers=(json gltf glb aff obj ply off stl png exr render)
merge=0
seed=0
readers=()
seconds=300
while [ $# -gt 0 ]; do
  case "$1" in
    --merge) merge=1 ;;
    --seed) seed=$2; shift ;;
    -h|--help) sed -n '2,26p' "$0"; exit 0 ;;
    all) readers=("${all_readers[@]}") ;;
    [0-9]*) seconds=$1 ;;
    *)
      if [[ " ${all_readers[*]} " == *" $1 "* ]]; then readers+=("$1")
      else echo "fuzz.sh: unknown reader '$1' (one of: ${all_readers[*]}, all)" >&2; exit 2; fi ;;
  esac
  shift
done
[ ${#readers[@]} -gt 0 ] || readers=("${all_readers[@]}")

build=build/asan
targets=()
for r in "${readers[@]}"; do targets+=("fuzz_$r"); done
if [ ! -f "$build/build.ninja" ]; then cmake --preset asan >/dev/null; fi
cmake --build "$build" -j "$(nproc 2>/dev/null || echo 2)" --target "${targets[@]}"

# A failed sanitizer check must end the input with a report and a stack, so libFuzzer saves it.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1:symbolize=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1:symbolize=1}"
# Stacks with function names and lines (clang-15 has no llvm-symbolizer of its own version).
if [ -z "${ASAN_SYMBOLIZER_PATH:-}" ] && command -v llvm-symbolizer >/dev/null; then
  export ASAN_SYMBOLIZER_PATH=$(command -v llvm-symbolizer)
fi

scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

# One reader's run: its report goes to $scratch/R.report and its exit status to $scratch/R.rc.
fuzz_one() {
  local r=$1 findings="$build/fuzz-findings/$1" start rc=0 reproducer before
  mkdir -p "$findings" "$scratch/$r"
  local seeds=(tests/fuzz/corpus/$r)
  if [ -d "tests/data/fuzz-regressions/$r" ]; then seeds+=("tests/data/fuzz-regressions/$r"); fi
  {
    echo "== fuzz $r: ${seconds}s, seed $seed"
    start=$(date +%s)
    # The first folder receives what the fuzzer finds: a scratch one, so the seeds stay untouched.
    # shellcheck disable=SC2086
    "$build/tests/fuzz/fuzz_$r" "$scratch/$r" "${seeds[@]}" \
        -dict="tests/fuzz/dict/$r.dict" -max_total_time="$seconds" -seed="$seed" \
        -timeout="${SPECULA_FUZZ_TIMEOUT:-10}" -rss_limit_mb="${SPECULA_FUZZ_RSS_MB:-2048}" \
        -malloc_limit_mb="${SPECULA_FUZZ_MALLOC_MB:-1024}" \
        -artifact_prefix="$findings/" -print_final_stats=1 ${SPECULA_FUZZ_FLAGS:-} \
        > "$scratch/$r.log" 2>&1 || rc=$?
    grep -E '^(#[0-9]+[[:space:]]+DONE|stat::number_of_executed_units|stat::new_units_added)' "$scratch/$r.log" || true
    echo "   $(( $(date +%s) - start ))s, $(ls "$scratch/$r" | wc -l) new inputs"
    if [ $rc -ne 0 ]; then
      echo "!! fuzz $r: finding (exit $rc); the end of its log:"
      grep -v -E '^#[0-9]+\s+(NEW|REDUCE|pulse|INITED|RELOAD)' "$scratch/$r.log" | tail -n 60
      reproducer=$(grep -oE "Test unit written to [^ ]+" "$scratch/$r.log" | tail -n 1 | sed 's/Test unit written to //')
      echo "!! reproducer: ${reproducer:-see $findings/}  (replay: $build/tests/fuzz/fuzz_$r ${reproducer:-FILE})"
    fi
    if [ $merge -eq 1 ] && [ -n "$(ls -A "$scratch/$r")" ]; then
      before=$(ls "tests/fuzz/corpus/$r" | wc -l)
      if "$build/tests/fuzz/fuzz_$r" -merge=1 "tests/fuzz/corpus/$r" "$scratch/$r" > "$scratch/$r.merge.log" 2>&1; then
        echo "   merged: tests/fuzz/corpus/$r has $(ls "tests/fuzz/corpus/$r" | wc -l) files (was $before)"
      else
        echo "!! fuzz $r: merge failed"; tail -n 20 "$scratch/$r.merge.log"; rc=1
      fi
    fi
  } > "$scratch/$r.report"
  echo $rc > "$scratch/$r.rc"
}

# libFuzzer runs on one core: SPECULA_FUZZ_JOBS fuzzers (default: one per core) run side by side,
# each still for its own SECONDS, and their reports are printed in the readers' order.
parallel=${SPECULA_FUZZ_JOBS:-$(nproc 2>/dev/null || echo 1)}
start_all=$(date +%s)
for r in "${readers[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$parallel" ]; do wait -n || true; done
  fuzz_one "$r" &
done
wait
failed=()
for r in "${readers[@]}"; do
  cat "$scratch/$r.report" 2>/dev/null || echo "!! fuzz $r: its run ended without a report"
  if [ "$(cat "$scratch/$r.rc" 2>/dev/null || echo 1)" != 0 ]; then failed+=("$r"); fi
done
echo "== fuzzing took $(( $(date +%s) - start_all ))s for ${#readers[@]} fuzzer(s), $parallel at a time"
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz.sh: findings in: ${failed[*]} (reproducers under $build/fuzz-findings/)" >&2
  exit 1
fi
