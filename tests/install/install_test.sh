#!/usr/bin/env bash
# Installs the build tree into a scratch prefix, then configures, builds and runs an outside
# project that finds Specula with find_package(Specula), and the game samples the same way.
set -euo pipefail
build_dir=$1
source_dir=$2
cxx_flags=${3:-}
linker_flags=${4:-}
cxx_compiler=${5:-}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" >/dev/null
test -f "$work/prefix/lib/cmake/Specula/SpeculaConfig.cmake"
test -f "$work/prefix/include/specula/ecs/registry.h"
test -f "$work/prefix/include/specula/scene/scene.h"
test -f "$work/prefix/include/specula/shared/scene_layout.h"
# No project header lands outside include/specula/ (nothing to collide with other libraries).
test -z "$(find "$work/prefix/include" -mindepth 1 -maxdepth 1 ! -name specula)"
cmake -S "$source_dir/tests/install/consumer" -B "$work/build" -G Ninja \
      -DCMAKE_PREFIX_PATH="$work/prefix" -DCMAKE_BUILD_TYPE=Release \
      ${cxx_compiler:+-DCMAKE_CXX_COMPILER="$cxx_compiler"} \
      -DCMAKE_CXX_FLAGS="$cxx_flags" -DCMAKE_EXE_LINKER_FLAGS="$linker_flags" >/dev/null
cmake --build "$work/build" >/dev/null
"$work/build/consumer" "$source_dir/samples/scenes/cornell_box.json"
# The game samples build on the installed package alone (their CMakeLists finds Specula when
# built on their own), and replay a recording headless.
cmake -S "$source_dir/samples/games" -B "$work/games" -G Ninja \
      -DCMAKE_PREFIX_PATH="$work/prefix" -DCMAKE_BUILD_TYPE=Release \
      ${cxx_compiler:+-DCMAKE_CXX_COMPILER="$cxx_compiler"} \
      -DCMAKE_CXX_FLAGS="$cxx_flags" -DCMAKE_EXE_LINKER_FLAGS="$linker_flags" >/dev/null
cmake --build "$work/games" >/dev/null
"$work/games/mirror_run" --headless --frames 600 --size 32x18 \
    --input "$source_dir/samples/games/mirror_run/demo_input.txt" --stats "$work/stats.json"
grep -q '"won": true' "$work/stats.json"
