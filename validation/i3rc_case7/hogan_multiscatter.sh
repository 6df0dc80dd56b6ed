#!/bin/sh
# Hogan's fast model (multiscatter 1.2: PVC small-angle, Hogan 2008, J. Atmos. Sci. 65, 3621;
# TDTS wide-angle, Hogan & Battaglia 2008, J. Atmos. Sci. 65, 3636) on I3RC Case 7 lidar
# experiments 1-6, from the input files Hogan ships for them (examples/i3rc_lidar_exp*.in), for
# comparison with lidarsim. multiscatter is not part of lidarsim: get it from
# http://www.met.reading.ac.uk/clouds/multiscatter/ (or the copy of 1.2.10 in the public GitHub
# repository mgrecu35/gmp_combined, Code/multiscatter-1.2.10), build it (`make`, gcc), then
#
#   sh validation/i3rc_case7/hogan_multiscatter.sh PATH/TO/multiscatter-1.2.x
#
# It writes validation/i3rc_case7/hogan_i3rc.csv: apparent backscatter [m-1 sr-1] per 15 m gate
# (apparent depth below the cloud top of the gate centre). Experiments 5 and 6 twice: with
# Hogan's droplet optics (g 0.8634, lidar ratio 19.41 sr, radius 11.96 um: the I3RC droplet
# phase function) and with those of the phase function lidarsim uses here (C.1 at 532 nm:
# g 0.8528, 19.22 sr, effective radius 6 um). Experiment 1 (isotropic) has no forward lobe:
# `-algorithms single radar`, as the comment of Hogan's input file asks (its old
# -no-forward-lobe). Below the base of the slab clouds (4-6) the TDTS output is NaN (zero
# extinction there), left empty.
set -eu
MS=$(cd "$1" && pwd)
BIN=$MS/bin/multiscatter
EX=$MS/examples
OUT=$(cd "$(dirname "$0")" && pwd)/hogan_i3rc.csv
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# multiscatter writes a file "junk" (its instrument summary) into the working directory.
cd "$TMP"
c1() { awk '/^#/{print;next} n==0{print;n=1;next} {$3="6e-06"; $4="19.2185"; $7="0.852825"; print}' "$1"; }
"$BIN" -quiet -algorithms single radar "$EX/i3rc_lidar_exp1.in" > "$TMP/1" 2>/dev/null
for e in 2 3 4 5 6; do "$BIN" -quiet "$EX/i3rc_lidar_exp$e.in" > "$TMP/$e" 2>/dev/null; done
for e in 5 6; do c1 "$EX/i3rc_lidar_exp$e.in" > "$TMP/in$e"; "$BIN" -quiet "$TMP/in$e" > "$TMP/${e}c" 2>/dev/null; done
{
  echo "# Hogan multiscatter 1.2 on I3RC Case 7 (examples/i3rc_lidar_exp*.in), apparent backscatter m-1 sr-1; made by hogan_multiscatter.sh"
  echo "depth_m,exp1,exp2,exp3,exp4,exp5_i3rc_droplet,exp5_c1_optics,exp6_i3rc_droplet,exp6_c1_optics"
  paste -d' ' "$TMP/1" "$TMP/2" "$TMP/3" "$TMP/4" "$TMP/5" "$TMP/5c" "$TMP/6" "$TMP/6c" |
    awk '{ if ($2 > 1500) exit; printf "%s", $2;
           for (k = 5; k <= 40; k += 5) { v = $k; if (v ~ /nan/ || v + 0 < 1e-15) v = ""; printf ",%s", v }
           printf "\n" }'
} > "$OUT"
echo "wrote $OUT"
