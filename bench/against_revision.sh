#!/usr/bin/env bash
# Speed against an earlier revision, measured in one run: builds specula_bench at REV in a git
# worktree (once; kept under build/bench-rev-<sha>), then runs the old and the new report tool
# alternately, ROUNDS times each, on the same sections, and prints one table per section with the
# median over the rounds of each figure and the ratio new / old (frame times: above 1 means the
# new code is slower; rays per second: above 1 means it is faster).
#
#   bench/against_revision.sh REV [ROUNDS] [-- specula_bench options]
#   bench/against_revision.sh 529ca1f 5 -- --sections whitted --frames 10
#
# The new tool is build/release/bench/specula_bench (cmake --preset release && cmake --build
# --preset release --target specula_bench). Only the whitted section's "frame ms" column and the
# primary section's Mrays/s columns are compared; the rest of each report is printed as it is.
set -euo pipefail
cd "$(dirname "$0")/.."
rev=${1:?usage: bench/against_revision.sh REV [ROUNDS] [-- specula_bench options]}
shift
rounds=5
if [ $# -gt 0 ] && [ "$1" != "--" ]; then rounds=$1; shift; fi
[ "${1:-}" = "--" ] && shift
options=("$@")
[ ${#options[@]} -eq 0 ] && options=(--sections whitted --frames 10)

sha=$(git rev-parse --short "$rev")
old_tree=build/bench-rev-$sha
if [ ! -x "$old_tree/build/release/bench/specula_bench" ]; then
  rm -rf "$old_tree"
  git worktree add --detach "$old_tree" "$sha" >/dev/null
  (cd "$old_tree" && cmake --preset release -DSPECULA_BUILD_TESTS=OFF >/dev/null &&
     cmake --build --preset release --target specula_bench >/dev/null)
fi
old=$old_tree/build/release/bench/specula_bench
new=build/release/bench/specula_bench
[ -x "$new" ] || { echo "build $new first (cmake --preset release && cmake --build --preset release --target specula_bench)" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for r in $(seq 1 "$rounds"); do
  "$old" --source-dir "$PWD" "${options[@]}" >"$work/old.$r"
  "$new" --source-dir "$PWD" "${options[@]}" >"$work/new.$r"
done

# Rows of the whitted table: | scene | size | frame ms | ... ; median of frame ms per scene.
python3 - "$work" "$rounds" "$sha" <<'EOF'
import statistics, sys, re
work, rounds, sha = sys.argv[1], int(sys.argv[2]), sys.argv[3]
def tables(path):
    out, section = {}, None
    for line in open(path):
        if line.startswith("### "):
            section = line[4:].strip()
        elif line.startswith("|") and section and not line.startswith("|---"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            out.setdefault(section, []).append(cells)
    return out
old = [tables(f"{work}/old.{r}") for r in range(1, rounds + 1)]
new = [tables(f"{work}/new.{r}") for r in range(1, rounds + 1)]
for section in new[0]:
    if section not in old[0]:
        continue
    header = new[0][section][0]
    print(f"\n### {section}: revision {sha} against the working tree, median of {rounds} alternating rounds\n")
    if "frame ms" in header:
        col = header.index("frame ms")
        print("| scene | size | old frame ms | new frame ms | new / old |\n|---|---|---:|---:|---:|")
        for i, row in enumerate(new[0][section][1:], start=1):
            o = statistics.median(float(t[section][i][col]) for t in old)
            n = statistics.median(float(t[section][i][col]) for t in new)
            print(f"| {row[0]} | {row[1]} | {o:.1f} | {n:.1f} | {n / o:.3f} |")
    else:
        cols = [i for i, h in enumerate(header) if "Mrays/s" in h]
        print("| " + header[0] + " | " + " | ".join(f"old {header[c]} | new {header[c]} | new / old" for c in cols) + " |")
        print("|---:|" + "---:|---:|---:|" * len(cols))
        for i, row in enumerate(new[0][section][1:], start=1):
            cells = []
            for c in cols:
                o = statistics.median(float(t[section][i][c]) for t in old)
                n = statistics.median(float(t[section][i][c]) for t in new)
                cells.append(f"{o:.1f} | {n:.1f} | {n / o:.2f}")
            print(f"| {row[0]} | " + " | ".join(cells) + " |")
EOF
