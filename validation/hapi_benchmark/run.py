"""HAPI 1.3 and lidarsim side by side on the same work (issue item 8), in one run.

Work: all CO2 lines of ../shared/data/hitran/CO2_626_6000-6400_HITRAN2016.par with 6300 <= nu <= 6400
cm-1, grid 6300-6400 cm-1 step 0.001 cm-1, 25 cm-1 wing (WavenumberWingHW=0), 1 atm, 296 K,
air-broadened, cross-sections in cm^2/molecule (HITRAN_units=True).

Usage (from the project root, HAPI in a venv under /tmp):
    python3 -m venv /tmp/hapienv && /tmp/hapienv/bin/pip install hitran-api numpy
    cargo build --release --example hapi_benchmark
    /tmp/hapienv/bin/python validation/hapi_benchmark/run.py [--hapi-repeat N]

Prints a Markdown table (also written to validation/hapi_benchmark/last_run.md).
"""
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

with contextlib.redirect_stdout(io.StringIO()):
    import hapi  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.environ.get("LIDARSIM_SHARED", os.path.join(ROOT, "..", "shared"))
PAR = os.path.join(SHARED, "data", "hitran", "CO2_626_6000-6400_HITRAN2016.par")
hapi_repeat = int(sys.argv[sys.argv.index("--hapi-repeat") + 1]) if "--hapi-repeat" in sys.argv else 1

with tempfile.TemporaryDirectory() as tmp:
    # The same lines for both codes: the records with 6300 <= nu <= 6400 (lidarsim filters the
    # same way, LineFilter::window(6300, 6400)).
    recs = [l for l in open(PAR) if 6300.0 <= float(l[3:15]) <= 6400.0]
    with open(os.path.join(tmp, "CO2.data"), "w") as f:
        f.writelines(recs)
    header = dict(hapi.HITRAN_DEFAULT_HEADER)
    header["table_name"] = "CO2"
    header["number_of_rows"] = len(recs)
    with open(os.path.join(tmp, "CO2.header"), "w") as f:
        json.dump(header, f)
    with contextlib.redirect_stdout(io.StringIO()):
        hapi.db_begin(tmp)

    hapi_times = []
    for _ in range(hapi_repeat):
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):
            nu, coef = hapi.absorptionCoefficient_Voigt(
                Components=[(2, 1)], SourceTables="CO2",
                WavenumberGrid=np.linspace(6300.0, 6400.0, 100001),
                WavenumberWing=25.0, WavenumberWingHW=0.0,
                Environment={"p": 1.0, "T": 296.0}, Diluent={"air": 1.0},
                HITRAN_units=True, IntensityThreshold=0.0)
        hapi_times.append(time.perf_counter() - t0)

    out = os.path.join(tmp, "lidarsim_sigma.bin")
    exe = os.path.join(ROOT, "target", "release", "examples", "hapi_benchmark")
    res = json.loads(subprocess.run([exe, "--out", out], check=True, capture_output=True,
                                    text=True).stdout)
    ours = np.fromfile(out, dtype="<f8")

assert len(ours) == len(coef) == 100001
rel_hapi = np.abs(ours / coef - 1.0)
t_hapi = min(hapi_times)
rows = [
    ("lines, grid points", f"{len(recs)}, {len(coef)}"),
    ("HAPI 1.3 absorptionCoefficient_Voigt, 1 core [s]", f"{t_hapi:.2f}"),
    ("lidarsim fast (multigrid), 1 thread, best / median [s]",
     f"{res['fast_1thread_best_s']:.4f} / {res['fast_1thread_median_s']:.4f}"),
    ("lidarsim fast (multigrid), 2 threads, best / median [s]",
     f"{res['fast_2threads_best_s']:.4f} / {res['fast_2threads_median_s']:.4f}"),
    ("speed-up vs HAPI, 1 thread (best)", f"{t_hapi / res['fast_1thread_best_s']:.0f}x"),
    ("speed-up vs HAPI, 2 threads (best)", f"{t_hapi / res['fast_2threads_best_s']:.0f}x"),
    ("lidarsim exact reference (errorfunctions, every line at every point), 2 threads [s]",
     f"{res['exact_reference_2threads_s']:.2f}"),
    ("max rel. error, lidarsim fast vs exact Faddeeva (all points)",
     f"{res['fast_vs_exact_max_rel_error']:.2e}"),
    ("max rel. difference, lidarsim fast vs HAPI (HAPI's own CPF hum1_wei error is ~1e-5..1e-4)",
     f"{rel_hapi.max():.2e}"),
]
md = "| quantity | value |\n|---|---|\n" + "\n".join(f"| {a} | {b} |" for a, b in rows) + "\n"
print(md)
with open(os.path.join(ROOT, "validation", "hapi_benchmark", "last_run.md"), "w") as f:
    f.write(md)
