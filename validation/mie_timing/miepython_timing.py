"""Side-by-side timing: miepython 3.3 (numba JIT) against `lidarsim mie` on the same spheres.

Setup (never committed):
    python3 -m venv /tmp/mievenv && /tmp/mievenv/bin/pip install miepython==3.3.0 numba
Run from the project root after `cargo build --release --examples`:
    MIEPYTHON_USE_JIT=1 /tmp/mievenv/bin/python validation/mie_timing/miepython_timing.py

Both sides: m = 1.33 - 1e-8 i (miepython's sign; lidarsim 1.33 + 1e-8 i), x = 10, 100, 1000,
10000; efficiencies only, and efficiencies plus S1, S2 at 181 angles. Each figure is the best of
5 repeats of a loop long enough to take ~0.3 s, in ms per particle. lidarsim's numbers come from
the `mie_timing` example (same loop structure, one thread).
"""
import os, subprocess, time
os.environ.setdefault("MIEPYTHON_USE_JIT", "1")
import numpy as np
import miepython as mp

def best_ms(f, n):
    f()  # JIT warm-up
    best = 1e9
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(n):
            f()
        best = min(best, (time.perf_counter() - t) / n * 1e3)
    return best

mu = np.cos(np.radians(np.arange(181.0)))
m = 1.33 - 1e-8j
print("x,miepython_eff_ms,miepython_s1s2_181_ms")
rows = []
for x in (10.0, 100.0, 1000.0, 10000.0):
    n = max(3, int(3000 / x))
    e = best_ms(lambda: mp.efficiencies_mx(m, x), n)
    s = best_ms(lambda: (mp.efficiencies_mx(m, x), mp.S1_S2(m, x, mu, norm="wiscombe")), max(2, n // 10))
    rows.append((x, e, s))
    print(f"{x:g},{e:.4g},{s:.4g}")
out = subprocess.run(["./target/release/examples/mie_timing"], capture_output=True, text=True, check=True)
print(out.stdout.strip())
