#!/usr/bin/env python3
"""HAPI's PROFILE_HT timed on the grid of `cargo bench --bench spectroscopy -- beyond_voigt`:
the 51 NIST lines of the CO2 30012 band (air-broadened, 1 atm, 296 K), 6300-6400 cm-1 every
0.001 cm-1. Usage: python3 validation/beyond_voigt/hapi_timing.py SHARED_DIR
(needs hitran-api and numpy: see README_hapi.md)."""
import csv
import sys
import time

import numpy as np
import hapi

shared = sys.argv[1] if len(sys.argv) > 1 else "../shared"
rows = list(csv.DictReader(open(f"{shared}/data/nist_30012/CO2_30012_NIST_SDNGP_LM.csv")))
nu = np.arange(6300.0, 6400.0 + 1e-9, 0.001)
p, t = 1.0, 296.0
start = time.time()
total = np.zeros_like(nu)
for r in rows:
    nu0 = float(r["nu"])
    g0 = float(r["gamma0_air"]) * p
    gd = nu0 / 2.99792458e10 * np.sqrt(2 * 1.380648813e-16 * t * np.log(2) / (43.98983 * 1.66053873e-24))
    total += hapi.PROFILE_HT(nu0, gd, g0, float(r["SD_gamma_air"]) * g0, float(r["delta0_air"]) * p,
                             0.0, float(r["nuVC_air"]) * p, 0.0, nu)
elapsed = time.time() - start
print(f"HAPI {hapi.HAPI_VERSION} PROFILE_HT: {len(rows)} lines x {len(nu)} points in {elapsed:.2f} s"
      f" = {elapsed / len(rows) / len(nu) * 1e9:.1f} ns per line-point")
