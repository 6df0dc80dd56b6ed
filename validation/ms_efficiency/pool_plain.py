#!/usr/bin/env python3
"""Pool independent runs of the plain local estimate of C.1 (files written by
`lidarsim bench --write-plain`) into one reference for `lidarsim bench --depth --plain`.

    python3 pool_plain.py OUT.csv RUN1.csv RUN2.csv ...

Per (field of view, depth) cell the pooled mean and per-photon variance are those of all the
runs' photons together: with n_i photons, mean m_i and variance v_i per run,
m = sum n_i m_i / N and v = sum n_i (v_i + m_i^2) / N - m^2, N = sum n_i. The runs must be
independent (different seeds): the plain estimate's variance deep in the cloud rests on rare
spikes, and only more photons catch more of them. The time per photon is the photon-weighted
mean (`--depth` takes the plain estimate's time from its own side-by-side run anyway).
"""
import csv
import sys

HEADER = "fov_full_angle_mrad,depth_m,ms_energy_j,var_per_photon_j2,s_per_photon,photons"


def main(out_path, in_paths):
    cells = {}
    order = []
    sources = []
    for path in in_paths:
        with open(path) as f:
            rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
        if not rows:
            sys.exit(f"{path}: no cells")
        sources.append(f"{path} ({int(float(rows[0]['photons']))} photons)")
        for r in rows:
            key = (r["fov_full_angle_mrad"], r["depth_m"])
            n = float(r["photons"])
            m = float(r["ms_energy_j"])
            v = float(r["var_per_photon_j2"])
            t = float(r["s_per_photon"])
            if key not in cells:
                cells[key] = [0.0, 0.0, 0.0, 0.0, 0]
                order.append(key)
            c = cells[key]
            c[0] += n
            c[1] += n * m
            c[2] += n * (v + m * m)
            c[3] += n * t
            c[4] += 1
    if any(c[4] != len(in_paths) for c in cells.values()):
        sys.exit("the runs do not have the same cells")
    n_total = int(cells[order[0]][0])
    with open(out_path, "w") as out:
        out.write(
            f"# plain local estimate of C.1, orders >= 2, {n_total} photons pooled from "
            + "; ".join(sources)
            + "\n"
        )
        out.write(HEADER + "\n")
        for key in order:
            n, s1, s2, st, _ = cells[key]
            m = s1 / n
            v = max(s2 / n - m * m, 0.0)
            out.write(f"{key[0]},{key[1]},{m:e},{v:e},{st / n:e},{int(n)}\n")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
