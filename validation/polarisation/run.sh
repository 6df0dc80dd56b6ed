#!/bin/sh
# Polarised multiple scattering (README.md beside this file): the C.1 cloud at 532 nm for a
# ground lidar (3e7 photons, about 2 minutes on 2 threads) and a CALIPSO-like space lidar
# (4e6 photons, about 1 minute), then the tables and figures. Results go to
# target/validation/polarisation; c1_depolarisation.csv, hu.csv, speed.csv and the PNGs are
# rewritten here.
set -eu
cd "$(dirname "$0")/../.."
OUT=target/validation/polarisation
mkdir -p "$OUT"
cargo build --release --bin lidarsim --example polarisation
./target/release/lidarsim run validation/polarisation/c1_532.toml --out "$OUT/c1" \
  --photons 30000000 --seed 7 --threads 2 --no-plots
./target/release/lidarsim run validation/polarisation/calipso.toml --out "$OUT/calipso" \
  --photons 4000000 --seed 7 --threads 2 --no-plots
./target/release/examples/polarisation "$OUT"
