"""What the Python package costs over the command line, measured side by side (a benchmark,
not a test: figures and ratios are printed, nothing is asserted).

1. A default run: `lidarsim run --out DIR --no-plots` against `lidarsim.run()` (the same
   scene, photons, seed and threads; the command line also writes its CSV files and run.nc).
2. Line by line: `lidarsim lbl --lines FILE …` against `lidarsim.cross_section(FILE, …)` for
   the same lines and grid (both read the line file; the command line also writes its CSV).
3. Copies: the result arrays of `run` are the buffers Rust filled (numpy owns the vectors);
   what is copied, and its size against the result's.

Each pair alternates, repeats (median of REPEATS) and uses the shipped release build of both
(`cargo build --release`; the wheel of scripts/test-python or `maturin build --release`).

    python python/benchmarks/overhead.py [--repeats 7] [--lines PAR]
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lidarsim
from lidarsim import _lidarsim
from lidarsim._data import to_xarray

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("LIDARSIM_BIN", ROOT / "target" / "release" / "lidarsim"))
SHARED = Path(os.environ.get("LIDARSIM_SHARED", ROOT.parent / "shared"))


def timed(fn):
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def pair(name, cli, py, repeats):
    a, b = [], []
    for _ in range(repeats):
        a.append(timed(cli))
        b.append(timed(py))
    ma, mb = statistics.median(a), statistics.median(b)
    print(f"{name}: command line {ma:.3f} s, Python {mb:.3f} s (median of {repeats}); "
          f"Python / command line = {mb / ma:.3f} ({100 * (mb / ma - 1):+.1f} %)")
    return ma, mb


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--lines", default=str(SHARED / "data/hitran/CO2_626_6000-6400_HITRAN2016.par"))
    a = ap.parse_args()
    out = tempfile.mkdtemp()
    run_args = ["--photons", str(a.photons), "--seed", "1", "--threads", str(a.threads)]
    pair(
        f"default run ({a.photons} photons, {a.threads} threads)",
        lambda: subprocess.run([str(BIN), "run", "--out", out, "--no-plots", *run_args], check=True, capture_output=True),
        lambda: lidarsim.run(photons=a.photons, seed=1, threads=a.threads),
        a.repeats,
    )
    lines = Path(a.lines)
    if lines.is_file():
        start, end, step = 6300.0, 6400.0, 0.0005
        nu = start + np.arange(int(round((end - start) / step)) + 1) * step
        pair(
            f"cross-sections ({lines.name}, {nu.size} points, 1 atm, 296 K)",
            lambda: subprocess.run([str(BIN), "lbl", "--lines", str(lines), "--pressure-atm", "1", "--temperature-k", "296",
                                    "--start-cm1", str(start), "--end-cm1", str(end), "--step-cm1", str(step),
                                    "--out", os.path.join(out, "xs.csv")], check=True, capture_output=True),
            lambda: lidarsim.cross_section(lines, 101_325.0, 296.0, nu),
            a.repeats,
        )
    else:
        print(f"cross-sections: skipped, {lines} is absent")
    # Copies: the arrays of the Dataset are the ones Rust handed over.
    scene = lidarsim.Scene.default()
    parts, _ = _lidarsim.run(scene._inner, a.photons, 1, a.threads, None, "")
    ds = to_xarray(parts)
    numeric = [(name, values) for name, _, values, _ in parts[1] if isinstance(values, np.ndarray)]
    copied = [name for name, values in numeric if not np.shares_memory(ds[name].values, values)]
    copied_bytes = sum(ds[name].nbytes for name in copied)
    print(f"copies: {len(numeric) - len(copied)} of {len(numeric)} numeric variables are the buffer "
          f"Rust filled; copied: {', '.join(copied) or 'none'} ({copied_bytes} bytes: pandas "
          f"indexes of dimension coordinates) of a {ds.nbytes} byte result")

if __name__ == "__main__":
    sys.exit(main())
