"""Side by side: lidarsim's Monte Carlo Jacobians and Hogan's multiscatter (an approximation:
PVC small-angle + TDTS wide-angle) on C.1 per gate and the CALIPSO-like case.

Usage: python compare.py LIDARSIM_C1_DIR LIDARSIM_CALIPSO_DIR
(each the --out directory of `lidarsim run <scene>.toml` with `jacobians = true`).
Writes comparison_c1.csv and comparison_calipso.csv and prints, per FOV and order, the median
ratio lidarsim/multiscatter of ∂E/∂ε (particle extinction at fixed albedo) over the bins both
give and lidarsim knows to 10 %. A report, not a test: multiscatter is an approximation.
"""
import csv
import statistics
import sys
import tomllib
from pathlib import Path

HERE = Path(__file__).parent


def layer_altitudes(scene):
    s = tomllib.loads((HERE / scene).read_text())
    return [(l["base_m"], l["top_m"]) for l in s["layer"]]


def lidarsim_rows(out_dir):
    rows = {}
    for r in csv.DictReader(open(Path(out_dir) / "jacobians.csv")):
        if r["quantity"] != "particle_extinction":
            continue
        key = (float(r["fov_full_angle_mrad"]), float(r["range_m"]), r["order"],
               round(float(r["layer_bottom_m"]), 3))
        rows[key] = (float(r["derivative_j_m"]), float(r["stderr_j_m"]))
    return rows


def compare(case, scene, ms_csv, out_dir):
    alts = layer_altitudes(scene)
    ours = lidarsim_rows(out_dir)
    table, ratios = [], {}
    for r in csv.DictReader(open(HERE / ms_csv)):
        if r["quantity"] != "particle_extinction" or r["order"] not in ("total", "1"):
            continue
        base = round(alts[int(r["layer"])][0], 3)
        # multiscatter's files name the orders `total` and `1`; lidarsim's `total` and `1st`.
        order = {"1": "1st"}.get(r["order"], r["order"])
        key = (float(r["fov_full_angle_mrad"]), float(r["range_m"]), order, base)
        if key not in ours:
            continue
        v, se = ours[key]
        ms = float(r["derivative"])
        table.append([case, *key, v, se, ms])
        if ms != 0 and v != 0 and se < 0.1 * abs(v):
            ratios.setdefault((key[0], key[2]), []).append(v / ms)
    with open(HERE / f"comparison_{case}.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "fov_full_angle_mrad", "range_m", "order", "layer_bottom_m",
                    "lidarsim_j_m", "lidarsim_stderr_j_m", "multiscatter_j_m"])
        w.writerows(table)
    print(f"{case}: {len(table)} bins side by side")
    for (fov, order), rs in sorted(ratios.items()):
        q = statistics.quantiles(rs, n=4) if len(rs) > 3 else [min(rs), statistics.median(rs), max(rs)]
        print(f"  FOV {fov:g} mrad, order {order}: {len(rs)} bins, lidarsim/multiscatter "
              f"median {statistics.median(rs):.3f} (quartiles {q[0]:.3f}–{q[-1]:.3f})")


if __name__ == "__main__":
    compare("c1", "c1_per_gate.toml", "multiscatter_c1.csv", sys.argv[1])
    compare("calipso", "calipso_like.toml", "multiscatter_calipso.csv", sys.argv[2])
