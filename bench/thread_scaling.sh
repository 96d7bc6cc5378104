#!/usr/bin/env bash
# Issue 14, item 5, on a machine with many cores: the training step at 2 threads (pinned to two
# cores, the process alone) against all the machine's threads, in alternate rounds, on a
# paper-scale frame (the spider mesh on an 8iVSLF-like grid, about 3.1M points), plus each
# count's phases. One command, so that a lent machine's few minutes suffice:
#
#   bench/thread_scaling.sh [TRANSCODE] [ROUNDS] [OUT_DIR]
#
# TRANSCODE defaults to target/release/transcode (a stripped copy travels more easily: the
# device tool carries at most 64 MiB), ROUNDS to 3, OUT_DIR to $OUT/scaling or /tmp/scaling.
# Writes frame.ply, each run's text and JSON (t2-R.*, tN-R.*) and summary.txt there.
# Method and past figures: docs/benchmarks/threads.md.
set -euo pipefail

bin=${1:-target/release/transcode}
rounds=${2:-3}
out=${3:-${OUT:-/tmp}/scaling}
mesh=testdata/meshes/spider/spider.obj

[ -x "$bin" ] || { echo "thread_scaling: no executable at $bin" >&2; exit 2; }
[ -f "$mesh" ] || { echo "thread_scaling: run from the repository root ($mesh not found)" >&2; exit 2; }
command -v taskset > /dev/null || { echo "thread_scaling: needs taskset (util-linux)" >&2; exit 2; }
mkdir -p "$out"
n=$(nproc)
[ "$n" -gt 2 ] || { echo "thread_scaling: $n CPUs; this compares 2 threads with more" >&2; exit 2; }

{
    echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $n CPUs"
    echo "binary: $bin, rounds: $rounds"
} | tee "$out/summary.txt"

if [ ! -f "$out/frame.ply" ]; then
    "$bin" synth --mesh "$mesh" --grid 4095 --points 3500000 --cameras 13 --out "$out/frame.ply" \
        > "$out/synth.txt" 2>&1
fi

bench() { # threads, tag, [taskset CPU list]
    local threads=$1 tag=$2
    shift 2
    RAYON_NUM_THREADS=$threads "$@" "$bin" bench --input "$out/frame.ply" --threads "$threads" \
        --repeats 3 --steps 20 --json "$out/$tag.json" > "$out/$tag.txt" 2>&1
}

for r in $(seq "$rounds"); do
    bench 2 "t2-$r" taskset -c 0,1
    bench "$n" "t$n-$r"
    echo "round $r done" >&2
done

python3 - "$out" "$n" "$rounds" << 'EOF' | tee -a "$out/summary.txt"
import json, statistics, sys

out, n, rounds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
phases = ["forward_ms", "loss_ms", "backward_ms", "adam_ms"]
ratios = []
for r in range(1, rounds + 1):
    two = json.load(open(f"{out}/t2-{r}.json"))["step"]
    many = json.load(open(f"{out}/t{n}-{r}.json"))["step"]
    ratio = two["step_ms"] / many["step_ms"]
    ratios.append(ratio)
    parts = ", ".join(
        f"{p[:-3]} {two[p]:.1f} -> {many[p]:.1f} ({two[p] / many[p]:.2f}x)" for p in phases
    )
    print(f"round {r}: step {two['step_ms']:.1f} ms (2 threads, CPUs 0-1) -> "
          f"{many['step_ms']:.1f} ms ({n} threads): {ratio:.2f}x; {parts}")
print(f"2 -> {n} threads, median of {rounds} rounds: {statistics.median(ratios):.2f}x "
      f"(issue 14 item 5 asks >= 6.5x from 2 to 16)")
EOF
