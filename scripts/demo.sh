#!/usr/bin/env bash
# Installs what is missing, builds Specula (release) and runs the main job on the default sample
# scene, printing its figures.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/deps.sh
jobs=$(nproc 2>/dev/null || echo 2)
cmake --preset release -DSPECULA_BUILD_TESTS=OFF >/dev/null
cmake --build --preset release -j "$jobs" --target specula
specula=build/release/editor/specula
scene=${1:-samples/scenes/cornell_box.json}

echo "== specula info $scene"
"$specula" info "$scene"
echo
echo "== sample scenes"
for s in samples/scenes/*.json samples/scenes/*.gltf; do
  [ -e "$s" ] || continue
  printf '%-40s ' "$s"
  "$specula" info "$s" | awk -F': *' '/^entities/{e=$2} /^triangles/{t=$2} /^lights/{l=$2}
                                     END{print "triangles " t ", lights " l ", entities " e}'
done
echo
echo "== specula render $scene (Whitted, Embree, 2 threads, 30 frames)"
"$specula" render "$scene" --backend embree --mode whitted --threads 2 --frames 30 \
  --stats build/release/demo-stats.json --out build/release/demo.png
echo
echo "== the same frame in cast mode, compared with the Whitted frame"
"$specula" render "$scene" --backend embree --mode cast --threads 2 --frames 1 --out build/release/demo-cast.png >/dev/null
"$specula" compare build/release/demo.png build/release/demo-cast.png
echo
echo "image: build/release/demo.png   stats: build/release/demo-stats.json"
