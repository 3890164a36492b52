#!/usr/bin/env bash
# Packs `specula` and `specula_bench` with every shared library they load that a stock Ubuntu
# 24.04 lacks, the sample scenes and the bunny, and a run.sh, into one folder (under 60 MB) that
# runs on a GPU machine with none of our packages installed: the same benchmark there as here.
#
#   scripts/gpu_bundle.sh [--build-dir DIR] [--out DIR] [--no-build]
#     --build-dir  where specula and specula_bench are (default build/ci); built there with ninja
#                  unless --no-build
#     --out        the bundle folder (default build/gpu-bundle; replaced), and OUT.tar.gz beside it
#   then, on the GPU machine:
#     BUNDLE/run.sh specula info
#     BUNDLE/run.sh specula render BUNDLE/samples/scenes/cornell_box.json --backend vulkan
#     BUNDLE/run.sh specula_bench --sections gpu --size 1024
#
# Left out: the C runtime every Ubuntu has (glibc's libc, libm, ld-linux; libstdc++ and libgcc_s,
# which Ubuntu 24.04 ships newer than Debian 12's, so ours must not shadow what the NVIDIA driver
# loads) and zlib (in the base image). libvulkan.so.1 goes in: a GPU machine has the NVIDIA ICD
# (/usr/share/vulkan/icd.d) but not necessarily the loader package.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build/ci"
out="$root/build/gpu-bundle"
do_build=1
while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) build="$(cd "$2" && pwd)"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --no-build) do_build=0; shift ;;
    *) echo "gpu_bundle.sh: unknown argument '$1'" >&2; exit 1 ;;
  esac
done

programs=(editor/specula bench/specula_bench)
if [ "$do_build" = 1 ]; then
  ninja -C "$build" -j2 specula specula_bench
fi
for p in "${programs[@]}"; do
  [ -x "$build/$p" ] || { echo "gpu_bundle.sh: $build/$p is missing (build it or drop --no-build)" >&2; exit 1; }
done

# Libraries a stock Ubuntu 24.04 provides (matched on the soname's stem).
in_base_system() {
  case "$1" in
    linux-vdso.so.*|ld-linux*|libc.so.*|libm.so.*|libpthread.so.*|libdl.so.*|librt.so.*) return 0 ;;
    libstdc++.so.*|libgcc_s.so.*|libz.so.*) return 0 ;;
  esac
  return 1
}

rm -rf "$out"
mkdir -p "$out/bin" "$out/lib" "$out/samples/models"
for p in "${programs[@]}"; do
  # Debug info is most of the binary; the bundle is for measuring, not debugging.
  strip --strip-debug -o "$out/bin/$(basename "$p")" "$build/$p"
  ldd "$build/$p" | awk '/=> \// {print $1, $3}' | while read -r soname path; do
    in_base_system "$soname" && continue
    [ -e "$out/lib/$soname" ] || strip --strip-unneeded -o "$out/lib/$soname" "$(readlink -f "$path")"
  done
done
cp -r "$root/samples/scenes" "$out/samples/"
cp "$root/samples/models/bunny.obj" "$out/samples/models/"

cat >"$out/run.sh" <<'EOF'
#!/usr/bin/env bash
# Runs a bundled program with the bundled libraries: run.sh specula|specula_bench ARGS...
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
program="${1:?usage: run.sh specula|specula_bench ARGS...}"
shift
export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# Vulkan tools print errors without a runtime directory.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
# The lent GPU machines mount the NVIDIA driver under /usr/local/nvidia; the loader did not find
# it through the system's manifest on an earlier machine (vk_icdGetInstanceProcAddr refused for
# libGLX_nvidia.so.0): name the driver's own manifest unless the caller chose one.
nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ] && [ -f "$nvidia_icd" ]; then
  export VK_DRIVER_FILES="$nvidia_icd"
  [ -d /usr/local/nvidia/lib64 ] && export LD_LIBRARY_PATH="$LD_LIBRARY_PATH:/usr/local/nvidia/lib64"
fi
case "$program" in
  specula) exec "$here/bin/specula" "$@" ;;
  # The bench finds samples/ under --source-dir: the bundle's own unless given.
  specula_bench)
    for a in "$@"; do [ "$a" = --source-dir ] && exec "$here/bin/specula_bench" "$@"; done
    exec "$here/bin/specula_bench" --source-dir "$here" "$@" ;;
  *) echo "run.sh: unknown program '$program' (specula or specula_bench)" >&2; exit 1 ;;
esac
EOF
chmod +x "$out/run.sh"

# Check: with only the bundle on the library path, every library outside the base system
# resolves into the bundle, and the programs start in an empty environment.
missing=0
for p in bin/specula bin/specula_bench; do
  while read -r soname path; do
    in_base_system "$soname" && continue
    case "$path" in
      "$out/lib/"*) ;;
      *) echo "gpu_bundle.sh: $p: $soname resolves to $path, not the bundle" >&2; missing=1 ;;
    esac
  done < <(env -i LD_LIBRARY_PATH="$out/lib" ldd "$out/$p" | awk '/=>/ {print $1, $3}')
done
[ "$missing" = 0 ] || exit 1
env -i PATH=/usr/bin:/bin "$out/run.sh" specula --version >/dev/null
env -i PATH=/usr/bin:/bin "$out/run.sh" specula info "$out/samples/scenes/cornell_box.json" >/dev/null
# The bench reads the bunny and the Cornell box from the bundle's samples/.
env -i PATH=/usr/bin:/bin "$out/run.sh" specula_bench --sections gpu --size 16 --repetitions 1 >/dev/null
size_mb=$(du -sm "$out" | cut -f1)
if [ "$size_mb" -gt 60 ]; then
  echo "gpu_bundle.sh: the bundle is ${size_mb} MB, over 60 MB" >&2
  exit 1
fi
# The device tool carries at most 64 MiB with the working tree: the bundle goes as a tarball
# (about 23 MB, gzip: a few seconds, where xz took half a minute), which scripts/gpu_measure.sh
# unpacks there.
tar -C "$(dirname "$out")" -czf "$out.tar.gz" "$(basename "$out")"
# The prepared script runs on the tarball as it will on a GPU machine (its quick steps, on tiny
# images): a lent machine's minutes are not spent finding a broken step.
check="$(mktemp -d)"
if ! SPECULA_GPU_STEPS="info stages" SPECULA_GPU_SIZE=16 "$root/scripts/gpu_measure.sh" \
  "$out.tar.gz" "$check" >"$check/log" 2>&1 || ! grep -q "^info: exit 0" "$check/steps.txt" ||
  ! grep -q "^stages: exit 0" "$check/steps.txt" || [ ! -s "$check/stages_cache_on.json" ]; then
  echo "gpu_bundle.sh: scripts/gpu_measure.sh failed on the bundle:" >&2
  tail -n 20 "$check/log" >&2
  exit 1
fi
rm -rf "$check"
echo "gpu_bundle.sh: $out (${size_mb} MB; $out.tar.gz $(du -m "$out.tar.gz" | cut -f1) MB): run.sh specula|specula_bench ARGS"
