#!/usr/bin/env bash
# The GPU figures of the Vulkan path in one run, for a lent GPU machine (the device tool): the
# devices seen, then issue 10's two targets — primary rays on the bunny at 1024² (trace_rays
# against the native scalar traversal, hits compared) and mirror_spheres_32 with caches on device
# frames at 1024² — then, time permitting, the whole gpu section. Each step is bounded by its own
# timeout, writes its report to OUT as it goes, and a step that fails does not stop the next.
#
#   here:   scripts/gpu_bundle.sh          (build/gpu-bundle and build/gpu-bundle.tar.gz, 23 MB)
#   there:  scripts/gpu_measure.sh [BUNDLE] [OUT]
#           BUNDLE: the bundle's folder or its .tar.gz (unpacked under /tmp); default
#           build/gpu-bundle.tar.gz, else build/gpu-bundle. OUT: default $OUT (the device
#           tool's), else ./gpu-out
#   device tool: run(command="scripts/gpu_measure.sh", carry=["build/gpu-bundle.tar.gz"],
#                    timeout_s=540)  (the folder itself is over the tool's 64 MiB with the tree)
#
# SPECULA_GPU_STEPS (default "info traversal cache stages gpu") picks the steps; SPECULA_GPU_THREADS the
# CPU threads of the native columns (default: every core); SPECULA_GPU_SIZE the image side
# (default 1024, the targets'; smaller for a try on lavapipe).
set -uo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bundle="${1:-}"
if [ -z "$bundle" ]; then
  bundle="$root/build/gpu-bundle.tar.gz"
  [ -f "$bundle" ] || bundle="$root/build/gpu-bundle"
fi
out="${2:-${OUT:-$root/gpu-out}}"
steps="${SPECULA_GPU_STEPS:-info traversal cache stages gpu}"
threads="${SPECULA_GPU_THREADS:-$(nproc)}"
size="${SPECULA_GPU_SIZE:-1024}"
mkdir -p "$out"
if [ -f "$bundle" ]; then
  unpacked=/tmp/specula-gpu
  rm -rf "$unpacked" && mkdir -p "$unpacked" && tar -C "$unpacked" -xzf "$bundle" ||
    { echo "gpu_measure.sh: cannot unpack $bundle" >&2; exit 1; }
  bundle="$(find "$unpacked" -maxdepth 2 -name run.sh -printf '%h\n' | head -n 1)"
fi
[ -x "$bundle/run.sh" ] || { echo "gpu_measure.sh: no bundle at $bundle (scripts/gpu_bundle.sh)" >&2; exit 1; }

# Runs one step: its name, its time limit in seconds, then the command; the report goes to
# OUT/NAME.md, the status to OUT/steps.txt.
step() {
  local name=$1 limit=$2
  shift 2
  case " $steps " in *" $name "*) ;; *) return 0 ;; esac
  local start=$SECONDS
  echo "== $name (at most ${limit} s)"
  timeout --kill-after=10 "$limit" "$@" >"$out/$name.md" 2>"$out/$name.err"
  local rc=$?
  echo "$name: exit $rc after $((SECONDS - start)) s" | tee -a "$out/steps.txt"
  tail -n 40 "$out/$name.md"
  [ -s "$out/$name.err" ] && tail -n 5 "$out/$name.err"
  return 0
}

{
  date -u
  uname -a
  command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv
} >"$out/machine.txt" 2>&1
cat "$out/machine.txt"

step info 60 "$bundle/run.sh" specula info "$bundle/samples/scenes/mirror_spheres_32.json"
# Target: >= 1 Grays/s primary rays, bunny, 1024².
step traversal 150 "$bundle/run.sh" specula_bench --sections gpu-traversal --size "$size" \
  --threads "$threads" --repetitions 5
# Target: mirror_spheres_32 with caches at >= 200 frames/s.
step cache 150 "$bundle/run.sh" specula_bench --sections gpu-cache --size "$size" --threads "$threads"
# Where a frame's time goes: each wavefront stage's device time, the submits and the host's part
# (frames[].ms less frames[].gpu.gpu_ms), cached and uncached, in stats files beside the reports.
step stages 60 bash -c '
  for cache in on off; do
    "$1/run.sh" specula render "$1/samples/scenes/mirror_spheres_32.json" --backend vulkan \
      --mode whitted --frames 30 --width "$2" --height "$2" --cache "$cache" \
      --stats "$3/stages_cache_$cache.json" || exit 1
  done' stages "$bundle" "$size" "$out"
step gpu 240 "$bundle/run.sh" specula_bench --sections gpu --size "$size" --threads "$threads" \
  --repetitions 3
echo "gpu_measure.sh: reports in $out"
