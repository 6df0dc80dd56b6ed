#!/bin/sh
# I3RC Phase 3 Case 7 lidar experiments 1-6 (README.md beside this file). lidarsim: 1e6 photons
# per experiment, 1-2.5 CPU-minutes each (about 10 in all); the peer C tracer
# (../shared/peers/lidarmc.c) on experiments 1, 2, 4 and 5 (the homogeneous conservative ones it
# can describe): 4 seeds of 5e5 photons each, about 5 CPU-minutes. Results go to
# target/validation/i3rc; i3rc_case7.csv and i3rc_case7.png are rewritten here.
set -eu
cd "$(dirname "$0")/../.."
SHARED=${LIDARSIM_SHARED:-../shared}
OUT=target/validation/i3rc
mkdir -p "$OUT"
cargo build --release --bin lidarsim --example i3rc_case7
for e in 1 2 3 4 5 6; do
  ./target/release/lidarsim run validation/i3rc_case7/exp$e.toml --out "$OUT/exp$e" --photons 1000000 --seed 11 --no-plots
done
if [ -f "$SHARED/peers/lidarmc.c" ]; then
  gcc -O3 -march=native -o "$OUT/lidarmc" "$SHARED/peers/lidarmc.c" -lm
  awk -F, 'NR > 1 && $1 + 0 == $1 { print $1 "," $2 }' phase_functions/c1_cloud_532nm.txt > "$OUT/phase.csv"
  # lidarmc is a ground lidar looking up: its cloud base plays the cloud top. Its 15 m bins
  # start at range 0, so the cloud starts at 1000.005 km (a multiple of 15 m) for its bins to
  # be the scene's gates; it has no cut at the last gate, so each photon runs until it leaves
  # the cloud (about 250 scatterings in experiments 1 and 2).
  for s in 1 2 3 4; do
    M="$OUT/lidarmc $OUT/phase.csv 500000 0.04 1000005"
    A="0 1 2.5e-3 -dr 15 -rmax 1001505 -seed $s"
    $M 1002505 $A -hg 0 > "$OUT/lmc_e1_$s.txt"
    $M 1002505 $A -hg 0.85 > "$OUT/lmc_e2_$s.txt"
    $M 1000505 $A -hg 0.85 > "$OUT/lmc_e4_$s.txt"
    $M 1000505 $A > "$OUT/lmc_e5_$s.txt"
  done
fi
./target/release/examples/i3rc_case7 "$OUT" "$OUT"
