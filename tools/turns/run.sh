#!/usr/bin/env bash
# `compare` on one scene, git revision REV against the working tree, the two builds taking
# turns: inside real physics steps, where the solver and the narrow phase run between two
# broadphase updates and evict what they read (the prefetching of stop 43 showed only there;
# `tools/ab` replays onto freshly copied sets, already cached). Each build's runs are
# summarised by their medians: the ratio (Rapier / canopy), canopy's ms per step and, where
# the build has the `phase-times` feature, canopy's phases (ms per step). Two runs of the same
# code differ by 10 to 20% on this VM, so take 6 turns or more and compare medians.
#
#   tools/turns/run.sh REV SCENE [TURNS]     (TURNS: 6 by default)
#
# REV is built from `git archive` in target/turns/src, with its own target folder
# (target/turns/target, kept between runs: a rebuild after the first only compiles canopy).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
rev="${1:?usage: tools/turns/run.sh REV SCENE [TURNS]}"
scene="${2:?usage: tools/turns/run.sh REV SCENE [TURNS]}"
turns="${3:-6}"
out="$root/target/turns"
mkdir -p "$out"

# Builds the compare example of the workspace at $1 into $3 (target folder $2), with the
# phase timers where that revision has them.
build() {
    local manifest="$1/Cargo.toml" target="$2" dest="$3"
    if ! CARGO_TARGET_DIR="$target" cargo build --quiet --release --features phase-times \
        --example compare --manifest-path "$manifest" 2>/dev/null; then
        CARGO_TARGET_DIR="$target" cargo build --quiet --release --example compare \
            --manifest-path "$manifest"
    fi
    cp "$target/release/examples/compare" "$dest"
}

build "$root" "$root/target" "$out/compare-new"
rm -rf "$out/src"
mkdir -p "$out/src"
git -C "$root" archive "$rev" | tar -x -C "$out/src"
build "$out/src" "$out/target" "$out/compare-old"

# One line per run: build, ratio, canopy ms per step, then the phases (if printed).
runs="$out/runs.txt"
: >"$runs"
for turn in $(seq 1 "$turns"); do
    for which in old new; do
        "$out/compare-$which" --scene "$scene" 2>&1 | awk -v b="$which" -v s="$scene" '
            $1 == s && /\|/ { split($0, f, "|"); split(f[2], t, " "); ratio = t[3]; sub("x", "", ratio); canopy = t[2] }
            /canopy phases/ { gsub(",", ""); for (i = 1; i <= NF; i++) if ($i ~ /^[0-9.]+$/) phases = phases " " $i }
            END { print b, ratio, canopy phases }' >>"$runs"
    done
    echo "turn $turn of $turns done" >&2
done

# Medians per build and column.
echo "build  ratio  canopy  [removals examine trees search pair-edits liveness finish] (ms per step)  [moved per step]  (medians of $turns runs)"
for which in old new; do
    cols=$(awk -v b="$which" '$1 == b { print NF - 1; exit }' "$runs")
    line="$which"
    for c in $(seq 2 $((cols + 1))); do
        m=$(awk -v b="$which" -v c="$c" '$1 == b { print $c }' "$runs" | sort -g |
            awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }')
        line="$line $m"
    done
    echo "$line"
done
echo "every run: $runs"
