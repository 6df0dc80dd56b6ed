"""Compare lidarsim's C.1 tables with shared/reference/c1_phase_{1064,532}.csv (miepython).

Run from the project root after regenerating the tables (see README.md):
    python3 validation/mie_c1/compare.py
Prints the max relative difference of P over all angles and in angle bands.
"""
import sys

def read(path, cols):
    rows, header = [], None
    for line in open(path):
        if line.startswith("#") or not line.strip():
            continue
        f = line.strip().split(",")
        if header is None:
            header = f
            continue
        rows.append([float(f[header.index(c)]) for c in cols])
    return rows

for wl in (1064, 532):
    ours = read(f"phase_functions/c1_cloud_{wl}nm.txt", ["theta_deg", "phase_4pi"])
    ref = read(f"../shared/reference/c1_phase_{wl}.csv", ["theta_deg", "P11_4pi"])
    assert len(ours) == len(ref) and all(abs(a[0] - b[0]) < 1e-9 for a, b in zip(ours, ref)), "angle grids differ"
    bands = [(0, 20), (20, 160), (160, 175), (175, 180.1)]
    out = []
    worst = max(abs(a[1] / b[1] - 1) for a, b in zip(ours, ref))
    for lo, hi in bands:
        d = max(abs(a[1] / b[1] - 1) for a, b in zip(ours, ref) if lo <= a[0] < hi)
        out.append(f"{lo}-{min(hi,180):g} deg: {d:.2e}")
    print(f"{wl} nm: max |P/P_ref - 1| = {worst:.2e} ({'; '.join(out)}); P(180) ours {ours[-1][1]:.5f} ref {ref[-1][1]:.5f}")
