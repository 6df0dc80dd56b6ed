#!/usr/bin/env bash
# Scaling figures of issue 12, item 5 (README.md beside this script): merge cost of 100 shards
# of the C.1 scene, and one C.1 run on 1 process against 2 shard processes at once plus their
# merge. Each timing is the best of REPEAT runs by wall time, printed as wall, user and system
# CPU seconds: on a shared machine the wall time depends on the other work, the CPU time much
# less, so the CPU seconds measure the cost of sharding (work added) and the wall time the
# speed-up actually seen.
#
#   validation/slurm/scaling.sh [PHOTONS] [REPEAT]      (defaults 1000000 and 3)
set -euo pipefail
PHOTONS=${1:-1000000}
REPEAT=${2:-3}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=$ROOT/target/release/lidarsim
SCENE=$ROOT/scenes/bissonnette_c1.toml
WORK=$(mktemp -d /tmp/lidarsim-scaling.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
[ -x "$BIN" ] || (cd "$ROOT" && cargo build --release)
now() { date +%s.%N; }
# `measure CMD…`: "wall user sys" of one run of CMD (a shell function may start and wait for
# background processes; their CPU time counts).
measure() { { TIMEFORMAT='%R %U %S'; time "$@" >/dev/null 2>&1; } 2>&1; }
best() { sort -g | head -1; }
cpu() { echo "$1" | awk '{printf "%.2f s wall, %.2f s CPU", $1, $2 + $3}'; }
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg); $(nproc) cores"

# The C.1 scene with 10^4 batches (the most a run may have), to see merge cost per batch.
sed 's/^max_order = 10$/max_order = 10\nbatches = 10000/' "$SCENE" |
    sed "s|\.\./phase_functions/|$ROOT/phase_functions/|" >"$WORK/c1_10k.toml"

for variant in "100:$SCENE" "10000:$WORK/c1_10k.toml"; do
    batches=${variant%%:*}
    scene=${variant#*:}
    dir=$WORK/shards_$batches
    t0=$(now)
    for i in $(seq 0 99); do
        "$BIN" run "$scene" --photons "$PHOTONS" --threads 1 --shard "$i/100" --out "$dir" >/dev/null
    done
    t_shards=$(echo "$(now) - $t0" | bc)
    size=$(du -sb "$dir" | cut -f1)
    times=$(for r in $(seq "$REPEAT"); do
        measure "$BIN" merge "$dir" --out "$WORK/merged_$batches" --no-plots
    done | best)
    echo "merge of 100 shards, $batches batches of C.1, $PHOTONS photons: $(cpu "$times") (shard files $size bytes in all; the 100 shards took $t_shards s one after another on 1 thread)"
done
"$BIN" run "$SCENE" --photons "$PHOTONS" --threads 1 --out "$WORK/single" --no-plots >/dev/null
cmp "$WORK/single/returns.csv" "$WORK/merged_100/returns.csv" && echo "merged returns.csv of 100 shards = single run, byte for byte"

# Strong scaling: 1 process (1 thread) against 2 shard processes at once (1 thread each) and
# their merge; and 1 process with 2 threads, for comparison.
pair() {
    rm -rf "$WORK/pair"
    "$BIN" run "$SCENE" --photons "$PHOTONS" --threads 1 --shard 0/2 --out "$WORK/pair" &
    local p0=$!
    "$BIN" run "$SCENE" --photons "$PHOTONS" --threads 1 --shard 1/2 --out "$WORK/pair" &
    local p1=$!
    wait "$p0" "$p1"
    "$BIN" merge "$WORK/pair" --out "$WORK/pair_merged" --no-plots
}
one=$(for r in $(seq "$REPEAT"); do
    measure "$BIN" run "$SCENE" --photons "$PHOTONS" --threads 1 --out "$WORK/one" --no-plots
done | best)
threads2=$(for r in $(seq "$REPEAT"); do
    measure "$BIN" run "$SCENE" --photons "$PHOTONS" --threads 2 --out "$WORK/two" --no-plots
done | best)
two=$(for r in $(seq "$REPEAT"); do measure pair; done | best)
cmp "$WORK/one/returns.csv" "$WORK/pair_merged/returns.csv" && echo "2-shard merge = 1-process run, byte for byte"
speedup() { echo "$1 $2" | awk '{printf "%.2f", $1 / $2}'; }
echo "C.1, $PHOTONS photons: 1 process, 1 thread: $(cpu "$one")"
echo "C.1, $PHOTONS photons: 2 processes at once (1 thread each) + merge: $(cpu "$two"); speed-up $(speedup "${one%% *}" "${two%% *}")"
echo "C.1, $PHOTONS photons: 1 process, 2 threads: $(cpu "$threads2"); speed-up $(speedup "${one%% *}" "${threads2%% *}")"
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
