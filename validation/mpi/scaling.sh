#!/usr/bin/env bash
# Strong scaling of one Bissonnette C.1 run over MPI ranks (README.md beside this file).
#
#   validation/mpi/scaling.sh SINGLE_BINARY MPI_BINARY [PHOTONS] [REPEATS]
#
# Prints one line per run: configuration, repeat, wall time of the whole command [s], the CPU
# time of all its processes (user + system) [s], the transport's own wall time from
# summary.json [s], and the load average, since on a shared machine other work changes them.
set -euo pipefail
single=$(realpath "$1")
mpi=$(realpath "$2")
photons=${3:-2000000}
repeats=${4:-5}
cd "$(dirname "$0")/../.."
scene=scenes/bissonnette_c1.toml
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

measure() {
    local label=$1
    shift
    for i in $(seq 1 "$repeats"); do
        local TIMEFORMAT='%R %U %S' wall user sys transport
        { time "$@" --out "$work/out" >/dev/null 2>"$work/stderr"; } 2>"$work/time"
        read -r wall user sys <"$work/time"
        transport=$(grep '"wall_s"' "$work/out/summary.json" | tr -dc '0-9.e-')
        printf '%-30s %d  wall %6.2f s  cpu %6.2f s  transport %6.2f s  load %s\n' "$label" "$i" \
            "$wall" "$(awk -v u="$user" -v s="$sys" 'BEGIN { print u + s }')" "$transport" \
            "$(cut -d' ' -f1 /proc/loadavg)"
    done
}

args=(run "$scene" --photons "$photons" --seed 1 --no-plots)
mpirun_=(mpirun --oversubscribe --allow-run-as-root)
measure "1 process, 1 thread" "$single" "${args[@]}" --threads 1
measure "mpirun -np 1, 1 thread" "${mpirun_[@]}" -np 1 "$mpi" "${args[@]}" --threads 1
measure "mpirun -np 2, 1 thread each" "${mpirun_[@]}" -np 2 "$mpi" "${args[@]}" --threads 1
# OpenMPI polls while a rank waits for its partner; on cores shared with other work, yielding
# instead gives the partner its time.
measure "mpirun -np 2, yield when idle" "${mpirun_[@]}" --mca mpi_yield_when_idle 1 -np 2 "$mpi" \
    "${args[@]}" --threads 1
measure "1 process, 2 threads" "$single" "${args[@]}" --threads 2
