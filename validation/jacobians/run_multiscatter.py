#!/usr/bin/env python3
"""Hogan's multiscatter on the two cases of cases.py, with its Jacobian, as the external side of
issue 40, item 2(c): lidarsim's Monte Carlo Jacobians beside those of a fast approximate model.

    MULTISCATTER_DIR=/path/to/multiscatter-1.2.10 /work/venv/bin/python validation/jacobians/run_multiscatter.py

multiscatter is not part of lidarsim and is not in this repository. Version 1.2.10 (Robin Hogan,
GNU LGPL 2.1 or later) is in the public GitHub repository mgrecu35/gmp_combined under
Code/multiscatter-1.2.10 (later versions: http://www.met.reading.ac.uk/clouds/multiscatter/,
Apache 2.0 since 2015). Without MULTISCATTER_DIR the script says so in one line and stops. It
builds only the library and bin/multiscatter (gcc, `make`) when the program is missing.

What multiscatter 1.2.10 gives (read from src/multiscatter_ascii.c and src/jacobian_linear.c):
`-jacobian` prints, for every input gate j (a row) and every output gate i and field of view
(columns, i + ifov*n), d beta'_i / d ext_j: beta' the apparent backscatter [m^-1 sr^-1] (particles
plus air), ext_j the particle extinction [m^-1] of gate j, at fixed single-scattering albedo,
asymmetry factor, radius and lidar ratio S (so the gate's backscatter ext/S grows with it), units
sr^-1. In this version it is a one-sided finite difference in double precision (ext_j multiplied by
exp(1e-4)), whether "-jacobian" or "-numerical-jacobian" is asked; the fast approximate ln-ln
Jacobian of jacobian.c is not reachable from the program. `-ext-only` keeps only this block.

What this script writes (multiscatter_c1.csv, multiscatter_calipso.csv), per field of view,
lidarsim gate i (observed; multiscatter runs on 10 sub-gates per lidarsim gate for accuracy, the
sums below are over them), particle layer k (one per cloud gate, its index in the scene's
[[layer]] list), quantity and order (total = small-angle PVC + wide-angle TDTS, "fast lidar";
1 = single scattering, "single none"):

* raw_value: d <beta'>_i / d x_k [sr^-1], <beta'>_i the mean over gate i's sub-gates, x_k the
  layer's coefficient changed in all its sub-gates. particle_extinction: from -jacobian (sum of
  the layer's rows); particle_absorption (k_abs at fixed sigma_sca and phase function) and
  particle_scattering (sigma_sca at fixed k_abs and phase function): central differences of two
  runs with the coefficient +-1 % of the layer's extinction, mapped to multiscatter's inputs
  (ext, ssa, S) so that the phase function, hence P(180) = 4 pi / (ssa S), stays fixed.
* raw_fd_pm1pct: the same derivative by central differences of two multiscatter runs (+-1 % of
  the layer's extinction); for particle_extinction the check of -jacobian's meaning.
* derivative: dE_i/dx_k [J m] in lidarsim's normalisation, E_i the energy of gate i:
  E_i = C sum_sub beta'_sub dr_sub / r_sub^2 with C = E0 eta A_tel the lidar constant of the scene,
  r the range from the lidar, so dE_i/dx_k = C sum_sub (d beta'_sub / d x_k) dr_sub / r_sub^2.
* raw_quantity: ms_jacobian_dbeta_dext (multiscatter -jacobian), fd_dbeta_dkabs or fd_dbeta_dsca
  (this script's central differences).
* beta_apparent (<beta'>_i), energy_j (E_i). C is 0.785398 J m^2 for C.1 (1 J, eta 1, 1 m
  telescope) and 0.0863938 J m^2 for the CALIPSO-like case (0.11 J, eta 1, 1 m telescope).

Rows where the layer lies entirely beyond the gate are left out, and rows where the model has
neither signal nor derivative (C.1 above the cloud in single scattering): time of flight makes those
derivatives zero in both models; the rest are zero in the model. multiscatter prints 6 significant digits; the finite differences
inherit about 1e-6 beta' / (2 %) of rounding.
"""
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

from cases import CASES, gate_centres, layer_name

HERE = os.path.dirname(os.path.abspath(__file__))
SUB = 10  # multiscatter sub-gates per lidarsim gate
STEP = 0.01  # finite-difference step, fraction of the layer's extinction


def find_multiscatter():
    d = os.environ.get("MULTISCATTER_DIR")
    if not d or not os.path.isdir(os.path.join(d, "src")):
        print("skip: set MULTISCATTER_DIR to a multiscatter-1.2.x source tree (see README.md)")
        sys.exit(0)
    exe = os.path.join(d, "bin", "multiscatter")
    if not os.path.exists(exe):
        os.makedirs(os.path.join(d, "lib"), exist_ok=True)
        # only the C library and program: the Fortran demos need gfortran and are not used here
        subprocess.run(["make", "-C", os.path.join(d, "src"), "../lib/libmultiscatter.a", "../bin/multiscatter"],
                       check=True, stdout=subprocess.DEVNULL)
    return os.path.abspath(exe)


class Medium:
    """multiscatter's sub-gate profile of one case, ordered from the lidar outward."""

    def __init__(self, case):
        c = self.c = CASES[case]
        self.case = case
        e = c["gate_edges_m"]
        self.ngate = len(e) - 1
        dz = (e[1] - e[0]) / SUB
        self.z = np.array([e[0] + dz * (s + 0.5) for s in range(self.ngate * SUB)])
        self.dr = abs(dz)
        self.gate_of = np.arange(self.ngate * SUB) // SUB
        n = len(self.z)
        self.ext = np.zeros(n)
        self.ssa = np.ones(n)
        self.S = np.full(n, c["layers"][0][6])
        self.g = np.full(n, c["layers"][0][4])
        self.radius = np.full(n, c["layers"][0][5])
        self.drop = np.zeros(n)
        self.air = np.zeros(n)
        self.layer_subs = []
        for lo, hi, ext, ssa, g, a, S, drop, _ in c["layers"]:
            sel = np.where((self.z > lo) & (self.z < hi))[0]
            self.layer_subs.append(sel)
            self.ext[sel], self.ssa[sel], self.g[sel] = ext, ssa, g
            self.radius[sel], self.S[sel], self.drop[sel] = a, S, drop
        if c["air"]:
            centres = gate_centres(case)
            self.air = np.array([c["air"](centres[k]) for k in self.gate_of])
        alt = c["lidar_altitude_m"]
        self.r = np.abs(self.z - alt)
        # Transmitter: lidarsim's Gaussian beam has exp(-2 psi^2 / b^2) with b half the full angle;
        # multiscatter's 1/e half-width is then b / sqrt(2). Pencil beam: 1e-9 rad.
        b = c["beam_full_angle_mrad"] * 0.5e-3
        self.rho_t = b / math.sqrt(2) if b > 0 else 1e-9
        self.fov = [f * 0.5e-3 for f in c["fov_full_angle_mrad"]]  # top-hat half-widths
        self.C = c["pulse_energy_j"] * c["optical_efficiency"] * math.pi * (c["telescope_diameter_m"] / 2) ** 2

    def text(self, ext=None, ssa=None, S=None):
        ext = self.ext if ext is None else ext
        ssa = self.ssa if ssa is None else ssa
        S = self.S if S is None else S
        c = self.c
        head = [len(self.z), c["wavelength_m"], c["lidar_altitude_m"], self.rho_t] + self.fov
        out = [" ".join(f"{v:.10g}" for v in head)]
        for j in range(len(self.z)):
            # range, ext, radius, S, air ext, ssa, g, air ssa, droplet fraction, pristine ice fraction
            out.append(f"{self.z[j]:.10g} {ext[j]:.12g} {self.radius[j]:.6g} {S[j]:.12g} {self.air[j]:.10g} "
                       f"{ssa[j]:.15g} {self.g[j]:.6g} 1 {self.drop[j]:g} 0")
        return "\n".join(out) + "\n"


def run(exe, text, algorithms, jacobian=False):
    args = [exe, "-quiet", "-algorithms", *algorithms] + (["-jacobian", "-ext-only"] if jacobian else [])
    # multiscatter writes a file "junk" (its instrument summary) into its working directory
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run(args, input=text, capture_output=True, text=True, check=True, cwd=tmp).stdout
    rows = [l.split() for l in out.splitlines() if l.strip() and not l.startswith("#")]
    a = np.array([[float(v) for v in r] for r in rows])
    return a


def beta(exe, med, algorithms, **kw):
    a = run(exe, med.text(**kw), algorithms)
    b = a[:, 4:4 + len(med.fov)]  # index, range, ext, radius, then one beta' per FOV
    return np.nan_to_num(b, nan=0.0)


def perturbed(med, k, quantity, sign):
    """Inputs with layer k's coefficient changed by sign * STEP * ext, phase function fixed."""
    ext, ssa, S = med.ext.copy(), med.ssa.copy(), med.S.copy()
    sel = med.layer_subs[k]
    d = sign * STEP * med.ext[sel]
    sca, e0 = med.ssa[sel] * med.ext[sel], med.ext[sel]
    if quantity == "particle_extinction":
        ext[sel] = e0 + d  # ssa and S fixed: sigma_sca, k_abs and beta all scale with ext
    else:
        sca2 = sca + d if quantity == "particle_scattering" else sca
        ext[sel] = e0 + d
        ssa[sel] = sca2 / ext[sel]
        # fixed phase function: P(180) = 4 pi / (ssa S) unchanged, so S' = S ssa / ssa'
        S[sel] = med.S[sel] * med.ssa[sel] / ssa[sel]
        # (with ssa = 1, k_abs - STEP ext < 0 gives ssa' > 1: the model's formulas are smooth
        # there, so the central difference is still the derivative of the model at k_abs = 0)
    return dict(ext=ext, ssa=ssa, S=S), d


QUANTITIES = ["particle_extinction", "particle_absorption", "particle_scattering"]
ORDERS = {"total": ["fast", "lidar"], "1": ["single", "none"]}


def main():
    exe = find_multiscatter()
    for case in ["c1", "calipso"]:
        med = Medium(case)
        n, nf, L = len(med.z), len(med.fov), len(med.layer_subs)
        w = med.dr / med.r ** 2  # energy weights of the sub-gates: E = C sum beta' dr / r^2
        rows = []
        check = []
        for order, alg in ORDERS.items():
            b0 = beta(exe, med, alg)
            jac = np.nan_to_num(run(exe, med.text(), alg, jacobian=True), nan=0.0)  # n x (n * nfov)
            assert jac.shape == (n, n * nf), jac.shape
            for q in QUANTITIES:
                for k in range(L):
                    (pp, d), (pm, _) = perturbed(med, k, q, +1), perturbed(med, k, q, -1)
                    fd = (beta(exe, med, alg, **pp) - beta(exe, med, alg, **pm)) / (2 * d[0])
                    if q == "particle_extinction":
                        raw = jac[med.layer_subs[k]].sum(axis=0).reshape(nf, n).T  # [sub, fov]
                        rq = "ms_jacobian_dbeta_dext"
                    else:
                        raw = fd
                        rq = "fd_dbeta_dkabs" if q == "particle_absorption" else "fd_dbeta_dsca"
                    for i in range(med.ngate):
                        subs = np.where(med.gate_of == i)[0]
                        if subs[-1] < med.layer_subs[k].min():
                            continue  # layer beyond the gate: zero by time of flight
                        for f in range(nf):
                            if not (raw[subs, f].any() or fd[subs, f].any() or b0[subs, f].any()):
                                continue  # nothing there in this model (C.1 above the cloud, order 1)
                            rows.append((
                                case, med.c["fov_full_angle_mrad"][f], float(med.r[subs].mean()),
                                float(med.z[subs].mean()), k, layer_name(case, k), q, order,
                                med.C * float(np.sum(raw[subs, f] * w[subs])), rq,
                                float(raw[subs, f].mean()), float(fd[subs, f].mean()),
                                float(b0[subs, f].mean()), med.C * float(np.sum(b0[subs, f] * w[subs])), med.C))
                            if q == "particle_extinction":
                                check.append((raw[subs, f].mean(), fd[subs, f].mean(), b0[subs, f].mean()))
        name = os.path.join(HERE, f"multiscatter_{case}.csv")
        with open(name, "w") as fh:
            fh.write("case,fov_full_angle_mrad,range_m,layer,quantity,order,derivative,"
                     "raw_quantity,raw_value,raw_fd_pm1pct,beta_apparent,energy_j\n")
            for r in rows:
                # layer k is the scene's k-th [[layer]] (its name, "gate LO-HI m", in layer_name())
                fh.write(f"{r[0]},{r[1]:g},{r[2]:.0f},{r[4]},{r[6]},{r[7]},{r[8]:.5e},"
                         f"{r[9]},{r[10]:.5e},{r[11]:.5e},{r[12]:.5e},{r[13]:.5e}\n")
        c = np.array(check)
        big = np.abs(c[:, 0]) > 1e-3 * np.abs(c[:, 0]).max()
        rel = np.abs(c[big, 0] - c[big, 1]) / np.abs(c[big, 1])
        print(f"{case}: {len(rows)} rows -> {os.path.basename(name)}; -jacobian vs +-1% central difference "
              f"(|d| > 1e-3 of the largest, {big.sum()} entries): median rel. diff {np.median(rel):.2e}, "
              f"max {rel.max():.2e}")


if __name__ == "__main__":
    main()
