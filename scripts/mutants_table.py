"""Fold one cargo-mutants run of one file into validation/mutation (called by mutants.sh).

usage: mutants_table.py MUTANTS_OUT OUTCOMES_TSV CSV FILE TOTAL COMMIT SAMPLE [--iterate]

Reads MUTANTS_OUT/outcomes.json; writes OUTCOMES_TSV (outcome <TAB> mutant, one line per mutant
of the sample, the list of mutant names in the file SAMPLE); replaces FILE's row of CSV
(file,mutants,caught,missed,unviable,timeouts,date,commit), where `mutants` counts the sample.
With --iterate, only some mutants of the sample were tested again (those the previous run
missed); each of the others keeps its outcome of the previous run (matched by name without line
and column, so that a run of cargo-mutants' own --iterate folds too).
"""
import datetime
import json
import re
import sys

NAMES = {
    "CaughtMutant": "caught",
    "MissedMutant": "missed",
    "Unviable": "unviable",
    "Timeout": "timeout",
}


def mutant_name(scenario):
    m = scenario.get("Mutant") if isinstance(scenario, dict) else None
    if m is None:
        return None
    if "name" in m:
        return m["name"]
    # Older layouts: file:line:col: replacement
    span = m.get("span", {}).get("start", {})
    return f'{m.get("file")}:{span.get("line")}:{span.get("column")}: {m.get("genre")} {m.get("replacement")}'


def strip_position(name):
    """`src/x.rs:12:5: replace …` → `src/x.rs: replace …`."""
    return re.sub(r"^([^:]+):\d+:\d+:", r"\1:", name)


def main():
    out_dir, tsv, csv, file, total, commit, sample_file = sys.argv[1:8]
    iterate = "--iterate" in sys.argv[8:]
    with open(sample_file) as fh:
        sample = [line.rstrip("\n") for line in fh if line.strip()]
    with open(f"{out_dir}/outcomes.json") as fh:
        outcomes = json.load(fh)["outcomes"]
    new = {}
    for o in outcomes:
        name = mutant_name(o["scenario"])
        if name is None:
            # The baseline: if the unmutated tree did not build or pass, no mutant was tested,
            # and the earlier outcomes must not be stamped with this commit.
            if o["summary"] != "Success":
                sys.exit(f"mutants_table.py: {out_dir}: the unmutated baseline failed ({o['summary']}): nothing recorded")
            continue
        summary = o["summary"]
        if summary not in NAMES:
            sys.exit(f"mutants_table.py: {out_dir}/outcomes.json: unknown outcome {summary!r} of {name}")
        new[name] = NAMES[summary]
    merged = {}
    if iterate:
        # Earlier outcomes by exact name; those whose names no longer occur (the file was
        # edited) by name without line:column, in source order.
        exact, moved = {}, {}
        with open(tsv) as fh:
            for line in fh:
                outcome, name = line.rstrip("\n").split("\t", 1)
                exact[name] = outcome
        for name, outcome in exact.items():
            if name not in sample:
                moved.setdefault(strip_position(name), []).append(outcome)
        for name in sample:
            if name in new:
                merged[name] = new[name]
            elif name in exact:
                merged[name] = exact[name]
            elif moved.get(strip_position(name)):
                merged[name] = moved[strip_position(name)].pop(0)
            else:
                sys.exit(f"mutants_table.py: {name}: neither tested now nor before")
    else:
        merged = new
        missing = [n for n in sample if n not in new]
        if missing:
            sys.exit(f"mutants_table.py: {len(missing)} mutants of the sample were not tested (run interrupted?), e.g. {missing[0]}")
    with open(tsv, "w") as fh:
        for name in sorted(merged):
            fh.write(f"{merged[name]}\t{name}\n")
    counts = {k: 0 for k in NAMES.values()}
    for v in merged.values():
        counts[v] += 1
    row = ",".join(
        [
            file,
            str(len(merged)),
            str(counts["caught"]),
            str(counts["missed"]),
            str(counts["unviable"]),
            str(counts["timeout"]),
            datetime.date.today().isoformat(),
            commit[:12],
        ]
    )
    with open(csv) as fh:
        lines = fh.read().splitlines()
    header, rows = lines[0], [r for r in lines[1:] if r and r.split(",")[0] != file]
    rows.append(row)
    rows.sort()
    with open(csv, "w") as fh:
        fh.write("\n".join([header] + rows) + "\n")
    viable = counts["caught"] + counts["missed"]
    score = 100.0 * counts["caught"] / viable if viable else float("nan")
    print(f"{file}: {len(merged)} of {total} tested, {counts['caught']} caught, "
          f"{counts['missed']} missed, {counts['unviable']} unviable, {counts['timeout']} timeouts "
          f"({score:.1f} % of viable caught)")
    for name, outcome in sorted(merged.items()):
        if outcome == "missed":
            print(f"  missed: {name}")


if __name__ == "__main__":
    main()
