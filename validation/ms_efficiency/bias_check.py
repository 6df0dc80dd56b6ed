"""Total-to-single ratio of C.1 at every field of view: lidarsim's run (MC total over the analytic
single scattering) against the C tracer's seeds (its total over its own single scattering,
summed over seeds; the error is the scatter of the per-seed ratios). Usage:
bias_check.py DIR OUT.csv, DIR holding run/returns.csv and c_*.txt."""
import csv
import glob
import math
import sys

out_dir, out_csv = sys.argv[1], sys.argv[2]
seeds = [f for f in sorted(glob.glob(f"{out_dir}/c_*.txt")) if open(f).read().strip()]
if len(seeds) < 2:
    sys.exit(f"{out_dir}: fewer than two C tracer outputs")
# lidarmc: r_m, then (single, total) per FOV, half-angles 0.05 to 5 mrad.
peer = {}
for f in seeds:
    for line in open(f):
        if line.startswith("#") or not line.strip():
            continue
        v = [float(x) for x in line.split()]
        peer.setdefault(v[0], []).append(v[1:])
total, single = {}, {}
for r in csv.DictReader(open(f"{out_dir}/run/returns.csv")):
    key = (float(r["fov_full_angle_mrad"]), float(r["range_m"]))
    if r["source"] == "mc" and r["order"] == "total":
        total[key] = (float(r["energy_j"]), float(r["stderr_j"]))
    if r["source"] == "analytic" and r["order"] == "1st":
        single[key] = float(r["energy_j"])
rows = []
for i, fov in enumerate([0.1, 0.5, 1.0, 2.0, 5.0, 10.0]):
    zs = []
    for range_m in sorted(peer):
        depth = range_m - 1000.0
        if not 0.0 < depth < 300.0:
            continue
        per_seed = [x[2 * i + 1] / x[2 * i] for x in peer[range_m] if x[2 * i] > 0]
        n = len(per_seed)
        mean = sum(per_seed) / n
        se_c = math.sqrt(sum((q - mean) ** 2 for q in per_seed) / (n - 1) / n)
        ratio_c = sum(x[2 * i + 1] for x in peer[range_m]) / sum(x[2 * i] for x in peer[range_m])
        t, st = total[(fov, range_m)]
        a = single[(fov, range_m)]
        z = (t / a - ratio_c) / math.hypot(st / a, se_c)
        zs.append(z)
        rows.append((depth, fov, t / a, st / a, ratio_c, se_c, z))
        print(f"{fov:>4} mrad {depth:5.0f} m: lidarsim {t / a:.4f} ± {st / a:.4f}, "
              f"C tracer {ratio_c:.4f} ± {se_c:.4f}, z {z:+.1f}")
    rms = math.sqrt(sum(z * z for z in zs) / len(zs))
    print(f"{fov} mrad: rms z {rms:.2f}, max |z| {max(abs(z) for z in zs):.2f} over {len(zs)} gates")
print(f"C tracer: {len(seeds)} seeds")
with open(out_csv, "w") as f:
    f.write("depth_m,fov_full_angle_mrad,ratio_lidarsim,stderr_lidarsim,ratio_lidarmc,stderr_lidarmc,z\n")
    for r in rows:
        f.write(",".join(f"{x:.6g}" for x in r) + "\n")
print(f"wrote {out_csv}")
