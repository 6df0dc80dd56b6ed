#!/usr/bin/env bash
# Mutation testing of given source files with cargo-mutants, the way it runs in reasonable time
# on a 2-core machine (validation/mutation/README.md):
#
#   scripts/mutants.sh [--iterate] [--per-file N] FILE...
#
# * The mutants are tested in a git worktree of HEAD (target/mutants/tree), in place, so the
#   working tree is never touched and every run measures a commit; its builds go to
#   target/mutants/target, release profile made incremental, without debug info, LTO or a
#   single code-generation unit: a mutant then rebuilds in about 10 s.
# * The whole test suite runs for every mutant, by cargo-nextest, which stops at the first
#   failing test; a mutant's tests time out after 600 s (the suite takes about 5 min alone on 2 cores).
# * A file with at most N mutants (default 60) gets all of them; a larger one a round-robin
#   sample of at least N (the first of k = ⌊mutants/N⌋ shards: every k-th mutant in source
#   order).
# * --iterate tests again only the mutants the file's last run missed (after new tests are
#   committed; by exact name, so not after edits to the file itself); the others keep their
#   outcome.
#
# Results: validation/mutation/outcomes/<file>.tsv (outcome and name of every mutant tested),
# one row per file in validation/mutation/mutants.csv
# (file,mutants,caught,missed,unviable,timeouts,date,commit), and cargo-mutants' own output
# (logs, diffs) in target/mutants/out/<file>.
#
# Needs cargo-mutants (`cargo install cargo-mutants --locked`, 27.1 here) and cargo-nextest.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"

iterate=()
per_file=60
files=()
while [ $# -gt 0 ]; do
    case "$1" in
        --iterate) iterate=(--iterate); shift ;;
        --per-file) per_file="$2"; shift 2 ;;
        -h|--help) sed -n '2,24p' "$0"; exit 0 ;;
        -*) echo "mutants.sh: unknown option $1" >&2; exit 2 ;;
        *) files+=("$1"); shift ;;
    esac
done
if [ ${#files[@]} -eq 0 ]; then
    echo "mutants.sh: name at least one source file (e.g. src/stats.rs)" >&2
    exit 2
fi
for f in "${files[@]}"; do
    [ -f "$f" ] || { echo "mutants.sh: $f: no such file" >&2; exit 2; }
done
command -v cargo-mutants >/dev/null || { echo "mutants.sh: cargo-mutants is not installed (cargo install cargo-mutants --locked)" >&2; exit 2; }

if ! git diff --quiet HEAD -- src tests; then
    echo "mutants.sh: note: uncommitted changes under src/ or tests/ are not measured (HEAD is)" >&2
fi
commit="$(git rev-parse HEAD)"
tree="$root/target/mutants/tree"
if [ -d "$tree" ]; then
    git -C "$tree" checkout --quiet --detach --force "$commit"
else
    mkdir -p "$root/target/mutants"
    git worktree add --quiet --detach "$tree" "$commit"
fi

export CARGO_PROFILE_RELEASE_INCREMENTAL=true
export CARGO_PROFILE_RELEASE_DEBUG=0
# The release profile's whole-program optimisation would rebuild everything for every mutant.
export CARGO_PROFILE_RELEASE_LTO=false
export CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16
export CARGO_TARGET_DIR="$root/target/mutants/target"
# The tests read "tests only" data from ../shared of the checkout; the worktree has none beside it.
export LIDARSIM_SHARED="${LIDARSIM_SHARED:-$root/../shared}"

results="$root/validation/mutation"
mkdir -p "$results/outcomes"
csv="$results/mutants.csv"
[ -f "$csv" ] || echo "file,mutants,caught,missed,unviable,timeouts,date,commit" > "$csv"

for f in "${files[@]}"; do
    slug="$(echo "$f" | sed 's|^src/||; s|/|__|g; s|\.rs$||')"
    out="$root/target/mutants/out/$slug"
    mkdir -p "$out"
    total="$(cd "$tree" && cargo mutants --list -f "$f" | wc -l)"
    shards=$(( total / per_file ))
    [ "$shards" -ge 1 ] || shards=1
    shard=()
    [ "$shards" -gt 1 ] && shard=(--shard "0/$shards" --sharding round-robin)
    echo "== $f: $total mutants, testing $(( (total + shards - 1) / shards )) (every k-th, k = $shards)"
    (cd "$tree" && cargo mutants --list -f "$f" "${shard[@]}") > "$out/sample.txt"
    select=("${shard[@]}")
    if [ ${#iterate[@]} -gt 0 ]; then
        # Only the mutants the last run did not catch, by exact name (cargo-mutants' own
        # --iterate would shard what is left: another sample). Names carry line and column:
        # after editing the file itself, run it whole. cargo-mutants 27.1 applies neither --re
        # nor --exclude-re to struct-field deletions ("delete field … from struct … expression"):
        # every such mutant of the file is tested again too, and mutants_table.py keeps only the
        # outcomes of the sample.
        tsv="$results/outcomes/$slug.tsv"
        [ -f "$tsv" ] || { echo "mutants.sh: --iterate: no earlier run of $f ($tsv)" >&2; exit 2; }
        select=()
        while IFS= read -r re; do select+=(--re "$re"); done < <(python3 -c '
import re, sys
for line in open(sys.argv[1]):
    outcome, name = line.rstrip("\n").split("\t", 1)
    if outcome in ("missed", "timeout"):
        print("^" + re.escape(name) + "$")
' "$tsv")
        if [ ${#select[@]} -eq 0 ]; then
            echo "== $f: nothing missed in the last run"
            continue
        fi
    fi
    # cargo-mutants exits non-zero when mutants are missed; the outcomes say what happened.
    (cd "$tree" && cargo mutants --in-place -f "$f" --profile release --test-tool nextest \
        "${select[@]}" --timeout 600 --build-timeout 900 --output "$out") || true
    python3 "$root/scripts/mutants_table.py" "$out/mutants.out" "$results/outcomes/$slug.tsv" \
        "$csv" "$f" "$total" "$commit" "$out/sample.txt" ${iterate:+--iterate}
done
