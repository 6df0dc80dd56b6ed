#!/bin/sh
# The seed paper's line-selection study (issue 9): 3 latitude classes x 300 NWP-perturbed
# profiles, on-lines around CO2 R16e and R26e. Usage: validation/line_selection/run.sh OUT_DIR
# [SHARED_DIR]. Needs the HITRAN2016 CO2 626 and H2O 161 files of ../shared/data/hitran for the
# select-lines part (tests-only data: read in place, never copied). About 1.5 minutes of CPU.
set -eu
out=${1:?usage: run.sh OUT_DIR [SHARED_DIR]}
shared=${2:-$(dirname "$0")/../../../shared}
bin=${LIDARSIM:-target/release/lidarsim}
on=R16e+0.0GHz,R16e+0.6GHz,R16e+1.2GHz,R16e+1.8GHz,R16e+2.2GHz,R26e+0.0GHz,R26e+0.6GHz,R26e+1.2GHz,R26e+1.8GHz,R26e+2.2GHz
# 1. The scene's instrument and retrievals over the ensembles, with the error budget.
"$bin" dial scenes/study_co2_ipda.toml --ensemble 300 --seed 1 --class all --on "$on" --out "$out/dial"
# 2. Sensitivities of on-line positions every 0.5 GHz within +-3 GHz of R16e and R26e, HITRAN2016
#    CO2 and H2O lines, the same ensembles (Figures 4 and 5).
positions=$(awk 'BEGIN { n = 0; split("6359.967244 6366.086989", c, " ");
  for (i = 1; i <= 2; i++) for (g = -3; g <= 3.0001; g += 0.5) {
    printf "%s%.5f", (n++ ? "," : ""), c[i] + g / 29.9792458 } }')
"$bin" select-lines --ensemble 300 --seed 1 --class all \
  --lines "$shared/data/hitran/CO2_626_6000-6400_HITRAN2016.par" \
  --lines "$shared/data/hitran/H2O_161_6000-6400_HITRAN2016.par" \
  --on-cm1 "$positions" --off-cm1 6360.61 --co2-ppm 420 --layer-m 1000 --out "$out/select"
