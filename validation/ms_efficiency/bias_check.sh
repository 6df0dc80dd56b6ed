#!/bin/sh
# Are lidarsim's C.1 means right deep in the cloud? The total-to-single ratio at every field of
# view (0.1-10 mrad) and every 10 m gate 0-300 m into the cloud, from lidarsim (3e7 photons,
# every variance reduction; about 2 CPU-minutes) against 1e9 photons of the independent plain
# local-estimate C tracer ../shared/peers/lidarmc.c (16 seeds of 6.25e7, two at a time; about
# 25 CPU-minutes). Writes bias_check.csv beside this file and prints the table (README.md).
set -eu
cd "$(dirname "$0")/../.."
SHARED=${LIDARSIM_SHARED:-../shared}
OUT=target/validation/bias_check
mkdir -p "$OUT"
if [ ! -f "$SHARED/peers/lidarmc.c" ]; then
  echo "no $SHARED/peers/lidarmc.c: nothing to compare with" >&2
  exit 1
fi
cargo build --release --bin lidarsim
gcc -O3 -march=native -o "$OUT/lidarmc" "$SHARED/peers/lidarmc.c" -lm
awk -F, 'NR > 1 && $1 + 0 == $1 { print $1 "," $2 }' phase_functions/bissonnette_c1_1064nm.txt > "$OUT/phase.csv"
seeds() {
  for s in "$@"; do
    "$OUT/lidarmc" "$OUT/phase.csv" 62500000 17.23e-3 1000 1300 0 6 0.5e-4 2.5e-4 0.5e-3 1e-3 2.5e-3 5e-3 -dr 10 -seed "$s" \
      > "$OUT/c_$s.txt" 2> /dev/null
  done
}
seeds 101 102 103 104 105 106 107 108 &
seeds 201 202 203 204 205 206 207 208
wait
./target/release/lidarsim run scenes/bissonnette_c1.toml --out "$OUT/run" --photons 30000000 \
  --seed 7 --no-plots --threads 2
python3 validation/ms_efficiency/bias_check.py "$OUT" validation/ms_efficiency/bias_check.csv
