#!/usr/bin/env bash
# Regenerates samples/models/bunny.obj from the npm package `bunny` (the Stanford bunny as JS
# arrays). The OBJ is committed, so builds and tests never fetch anything; run this only to
# re-create it.
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack bunny@1.0.1 >/dev/null 2>&1 && tar xzf bunny-1.0.1.tgz)
node -e '
const b = require(process.argv[1]);
const lines = ["# Stanford bunny (Stanford 3D Scanning Repository), from the npm package bunny@1.0.1",
               "# " + b.positions.length + " vertices, " + b.cells.length + " triangles"];
for (const p of b.positions) lines.push("v " + p.join(" "));
for (const c of b.cells) lines.push("f " + c.map(i => i + 1).join(" "));
process.stdout.write(lines.join("\n") + "\n");
' "$work/package/index.js" > samples/models/bunny.obj
echo "wrote samples/models/bunny.obj"
