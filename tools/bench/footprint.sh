#!/bin/sh
# Memory one macro step reaches, for Tether and for the C floor
# (docs/performance.md, "Memory touched per step").
#
# Runs the `steps` example under callgrind's cache model with one fully
# associative LRU cache of each SIZE (bytes, a multiple of 64): a macro step
# whose data fits in SIZE misses nothing there once warm. Two runs of different
# length cancel the setup, as for the instruction counts. Needs valgrind.
#
# The two runs of each size go side by side; a size takes a few minutes.
#
#   tools/bench/footprint.sh [SIZE ...]      default: 4096 6144 8192 12288 14336 16384
set -eu
cd "$(dirname "$0")/../.."
for tool in valgrind callgrind_annotate; do
    command -v "$tool" >/dev/null || { echo "footprint.sh: needs $tool (valgrind)" >&2; exit 1; }
done
cargo build --release -q -p tether-bench --example steps
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
[ $# -gt 0 ] || set -- 4096 6144 8192 12288 14336 16384
misses() { # file -> LL read + write misses of the whole run
    callgrind_annotate "$1" 2>/dev/null | grep "PROGRAM TOTALS" | tr -d , | awk '{print $15 + $17}'
}
for size in "$@"; do
    for who in tether floor; do
        flag=""
        [ "$who" = floor ] && flag=--floor
        for n in 2000 4000; do
            valgrind --tool=callgrind --cache-sim=yes --D1=1024,16,64 \
                --LL="$size,$((size / 64)),64" --callgrind-out-file="$out/$who.$n" \
                target/release/examples/steps "$n" $flag >/dev/null 2>&1 &
        done
        wait
        a=$(misses "$out/$who.2000")
        b=$(misses "$out/$who.4000")
        echo "$who: $size-byte cache, $(((b - a) / 2000)) misses per macro step"
    done
done
