#!/usr/bin/env bash
# MPI runs against single-process runs: the files of `mpirun -np K lidarsim run` must equal,
# byte for byte, those of one process with the same scene and seed (summary.json without its
# wall time). Fails (exit 1) on any difference, and on a run that hangs.
#
#   validation/mpi/check.sh SINGLE_BINARY MPI_BINARY
#
# SINGLE_BINARY is a default build (no MPI code at all: the independent truth); MPI_BINARY a
# build with `--features mpi`. Called by .ci/run; runs as root there, hence --allow-run-as-root.
set -euo pipefail
single=$(realpath "$1")
mpi=$(realpath "$2")
cd "$(dirname "$0")/../.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# A hang must fail CI, not use up its time: every run gets a deadline.
mpirun_() {
    timeout 300 mpirun --oversubscribe --allow-run-as-root "$@"
}

# The single process uses as many threads as the ranks together, so that summary.json's
# `threads` (the total over the ranks) matches too.
compare() {
    local name=$1 ranks=$2 photons=$3 scene=$4
    shift 4
    local args=(--photons "$photons" --seed 7 "$@")
    if [ -n "$scene" ]; then args=("$scene" "${args[@]}"); fi
    timeout 300 "$single" run "${args[@]}" --threads "$ranks" --out "$work/$name-single" >/dev/null
    mpirun_ -np "$ranks" "$mpi" run "${args[@]}" --threads 1 --out "$work/$name-mpi" >/dev/null
    local ok=1
    for f in returns.csv signals.csv retrieval.csv returns.png dial.png; do
        if [ -e "$work/$name-single/$f" ] || [ -e "$work/$name-mpi/$f" ]; then
            cmp "$work/$name-single/$f" "$work/$name-mpi/$f" || ok=0
        fi
    done
    diff <(grep -v '"wall_s"' "$work/$name-single/summary.json") \
         <(grep -v '"wall_s"' "$work/$name-mpi/summary.json") || ok=0
    if [ "$ok" = 1 ]; then
        echo "mpi check: $name, $ranks ranks: identical to one process ($(wc -l <"$work/$name-mpi/returns.csv") rows in returns.csv)"
    else
        echo "mpi check: $name, $ranks ranks: DIFFERS from one process" >&2
        exit 1
    fi
}

# The default scene (laser line shapes: combined channels and on/off covariances, a retrieval),
# the C.1 cloud (multiple scattering, DDIS), and 3 ranks for 100 batches (uneven shares).
compare default 2 20000 ""
compare c1 2 20000 scenes/bissonnette_c1.toml
compare c1-3ranks 3 3000 scenes/bissonnette_c1.toml
# No Monte Carlo at all: the ranks agree there is nothing to trace.
compare analytic 2 0 scenes/airborne_co2_dial.toml

# Errors end the whole job with one message from rank 0, not a hang.
printf '[lidar]\npulse_energy_j = -1\n' >"$work/bad.toml"
status=0
mpirun_ -np 2 "$mpi" run "$work/bad.toml" --out "$work/bad" 2>"$work/bad.err" >/dev/null || status=$?
if [ "$status" = 0 ] || [ "$status" = 124 ] || ! grep -q 'lidarsim: error:' "$work/bad.err"; then
    echo "mpi check: a bad scene under mpirun hung or gave no message (status $status):" >&2
    cat "$work/bad.err" >&2
    exit 1
fi
echo "mpi check: a bad scene ends every rank with status $status"

# A run that fails on rank 0 before the Monte Carlo (the on- and off-lines swapped: the
# retrieval is refused) while rank 1 has built its plan: rank 0's message, once.
sed 's/^on = "on"/on = "SWAP"/; s/^off = "off"/off = "on"/; s/^on = "SWAP"/on = "off"/' \
    scenes/spaceborne_co2_ipda.toml >"$work/swapped.toml"
expect_refusal() {
    local name=$1 pattern=$2
    shift 2
    local status=0
    mpirun_ "$@" 2>"$work/$name.err" >/dev/null || status=$?
    if [ "$status" = 0 ] || [ "$status" = 124 ] || [ "$(grep -c "$pattern" "$work/$name.err")" != 1 ]; then
        echo "mpi check: $name: status $status, expected one message matching '$pattern':" >&2
        cat "$work/$name.err" >&2
        exit 1
    fi
    echo "mpi check: $name: one message, status $status"
}
expect_refusal "refused on rank 0" 'lidarsim: error: .*retrieval.on' \
    -np 2 "$mpi" run "$work/swapped.toml" --photons 2000 --out "$work/swapped"
# Ranks that would run different plans (here another seed on rank 1) stop before tracing.
expect_refusal "ranks disagree" 'lidarsim: error: on rank 1: it planned' \
    -np 1 "$mpi" run scenes/bissonnette_c1.toml --photons 2000 --seed 1 --out "$work/disagree" : \
    -np 1 "$mpi" run scenes/bissonnette_c1.toml --photons 2000 --seed 2 --out "$work/disagree"
for d in bad swapped disagree; do
    if [ -e "$work/$d" ]; then
        echo "mpi check: a refused run wrote $work/$d" >&2
        exit 1
    fi
done
