#!/bin/sh
# The Platt relation on the C.1 cloud at optical depths 1, 3 and 10 (README.md beside this file).
# lidarsim: 2e6 photons per cloud, 1-2 CPU-minutes each. Results go to target/validation/platt;
# platt.csv and platt.png are rewritten here.
set -eu
cd "$(dirname "$0")/../.."
OUT=target/validation/platt
mkdir -p "$OUT"
cargo build --release --bin lidarsim --example platt
for t in 1 3 10; do
  ./target/release/lidarsim run validation/platt/tau$t.toml --out "$OUT/tau$t" --photons 2000000 --seed 5 --no-plots
done
./target/release/examples/platt "$OUT"
