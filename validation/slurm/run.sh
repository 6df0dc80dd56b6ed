#!/usr/bin/env bash
# Stand up a real single-node Slurm on this machine, run a C.1 scene as a job array of shards
# plus a dependent merge job, and check the merged returns.csv equals a single run byte for
# byte (issue 12, item 2). Needs root (Debian packages, daemons). Not in CI: see README.md.
#
#   validation/slurm/run.sh [SHARDS] [PHOTONS]      (defaults 4 and 1000000)
#
# Everything Slurm needs lives in a fresh work directory (slurm.conf via SLURM_CONF, state,
# logs, pid files); /etc/slurm is not touched. The daemons this script starts (munged,
# slurmctld, slurmd) are stopped by their pids when it ends.
set -euo pipefail

N=${1:-4}
PHOTONS=${2:-1000000}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=$ROOT/target/release/lidarsim
SCENE=$ROOT/scenes/bissonnette_c1.toml
WORK=$(mktemp -d /tmp/lidarsim-slurm.XXXXXX)
chmod 755 "$WORK" # the munge user must reach its socket directory
HOST=$(hostname -s)
T0=$(date +%s.%N)
stamp() { printf '[%6.1f s] %s\n' "$(echo "$(date +%s.%N) - $T0" | bc)" "$*"; }

[ "$(id -u)" = 0 ] || { echo "run as root (packages and daemons)" >&2; exit 2; }
[ -x "$BIN" ] || (cd "$ROOT" && cargo build --release)

# 1. Packages.
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    stamp "installing slurm-wlm and munge"
    DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge >"$WORK/apt.log" 2>&1
fi
stamp "$(slurmctld -V), $(munged -V 2>&1 | head -1)"

PIDS=()
cleanup() {
    # Stop only what this script started, by pid, newest first.
    for ((i = ${#PIDS[@]} - 1; i >= 0; i--)); do
        f=${PIDS[i]}
        [ -s "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
    done
    sleep 1
}
trap cleanup EXIT

# 2. munge: the key the package made (or a new one), the daemon as the munge user.
[ -s /etc/munge/munge.key ] || mungekey --create --keyfile=/etc/munge/munge.key
chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
mkdir -p "$WORK/munge"
chown munge:munge "$WORK/munge"
chmod 755 "$WORK/munge"
MUNGE_SOCKET=$WORK/munge/munge.socket
runuser -u munge -- /usr/sbin/munged --socket="$MUNGE_SOCKET" \
    --pid-file="$WORK/munge/munged.pid" --log-file="$WORK/munge/munged.log" \
    --seed-file="$WORK/munge/munged.seed"
PIDS+=("$WORK/munge/munged.pid")
munge --socket="$MUNGE_SOCKET" -n | unmunge --socket="$MUNGE_SOCKET" >/dev/null
stamp "munged up (socket $MUNGE_SOCKET)"

# 3. A minimal slurm.conf: this host as the one node, no cgroups, no accounting.
CPUS=$(nproc)
MEM_MB=$(slurmd -C | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
mkdir -p "$WORK/state" "$WORK/spool" "$WORK/log"
export SLURM_CONF=$WORK/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=lidarsim
SlurmctldHost=$HOST
SlurmUser=root
AuthType=auth/munge
AuthInfo=socket=$MUNGE_SOCKET
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=local Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
slurmctld -f "$SLURM_CONF"
PIDS+=("$WORK/slurmctld.pid")
slurmd -f "$SLURM_CONF"
PIDS+=("$WORK/slurmd.pid")
for _ in $(seq 60); do
    state=$(sinfo -h -n "$HOST" -o %T 2>/dev/null || true)
    [ "$state" = idle ] && break
    sleep 1
done
[ "$state" = idle ] || { echo "node $HOST is '$state', not idle"; tail -20 "$WORK"/log/*.log; exit 1; }
stamp "slurmctld and slurmd up: $(sinfo -h -o '%P %D %C %T')"

# 4. The job array of shards and the merge that waits for it (the README's example).
cd "$WORK"
cat >shards.sbatch <<JOB
#!/bin/bash
#SBATCH --job-name=c1-shards
#SBATCH --array=0-$((N - 1))
#SBATCH --cpus-per-task=1
#SBATCH --output=shard-%a.out
"$BIN" run "$SCENE" --photons $PHOTONS --threads \$SLURM_CPUS_PER_TASK \\
    --shard \$SLURM_ARRAY_TASK_ID/$N --out shards --no-plots
JOB
JOBID=$(sbatch --parsable shards.sbatch)
stamp "submitted array job $JOBID (shards 0-$((N - 1)) of $N, $PHOTONS photons)"
sbatch --parsable --job-name=c1-merge --dependency=afterok:"$JOBID" --output=merge.out \
    --wait --wrap "\"$BIN\" merge shards --out merged --no-plots" >merge.jobid
stamp "merge job $(cat merge.jobid) done (after array $JOBID)"
cat shard-*.out merge.out | grep -v '^  channel'

# 5. The single run, and the comparison.
"$BIN" run "$SCENE" --photons $PHOTONS --threads "$CPUS" --out single --no-plots | tail -1
stamp "single run done"
if cmp single/returns.csv merged/returns.csv; then
    stamp "OK: merged returns.csv ($(wc -l <merged/returns.csv) lines, sha256 $(sha256sum merged/returns.csv | cut -c1-16)) equals the single run byte for byte"
else
    stamp "FAIL: merged returns.csv differs from the single run"
    exit 1
fi
