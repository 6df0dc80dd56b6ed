#!/bin/sh
# Bissonnette et al. (1995) C.1: multiple-to-single ratio against depth (README.md beside this
# file). lidarsim: 3e7 photons, about 1 CPU-minute; the peer C tracer (../shared/peers/lidarmc.c,
# plain local estimate): 8 seeds of 1e7 photons, about 2 CPU-minutes. Results go to
# target/validation/c1; the table is printed, c1_ratio.csv and c1_ratio.png are rewritten here.
set -eu
cd "$(dirname "$0")/../.."
SHARED=${LIDARSIM_SHARED:-../shared}
OUT=target/validation/c1
mkdir -p "$OUT"
cargo build --release --bin lidarsim --example c1_multiple_scattering
./target/release/lidarsim run scenes/bissonnette_c1.toml --out "$OUT/run" --photons 30000000 --seed 7 --no-plots
if [ -f "$SHARED/peers/lidarmc.c" ]; then
  gcc -O3 -march=native -o "$OUT/lidarmc" "$SHARED/peers/lidarmc.c" -lm
  # lidarmc reads theta_deg,P rows: the same table as the scene's.
  awk -F, 'NR > 1 && $1 + 0 == $1 { print $1 "," $2 }' phase_functions/bissonnette_c1_1064nm.txt > "$OUT/phase.csv"
  for s in 1 2 3 4 5 6 7 8; do
    "$OUT/lidarmc" "$OUT/phase.csv" 10000000 17.23e-3 1000 1300 0 6 0.5e-4 2.5e-4 0.5e-3 1e-3 2.5e-3 5e-3 \
      -dr 10 -seed $s > "$OUT/lmc_c1_$s.txt"
  done
  PEER="$OUT/lmc_c1_1.txt $OUT/lmc_c1_2.txt $OUT/lmc_c1_3.txt $OUT/lmc_c1_4.txt $OUT/lmc_c1_5.txt $OUT/lmc_c1_6.txt $OUT/lmc_c1_7.txt $OUT/lmc_c1_8.txt"
else
  echo "no $SHARED/peers/lidarmc.c: comparing with Hogan's model only"
  PEER=
fi
# shellcheck disable=SC2086
./target/release/examples/c1_multiple_scattering "$OUT/run" $PEER
