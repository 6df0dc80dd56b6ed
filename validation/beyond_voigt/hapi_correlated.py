"""Hartmann-Tran profiles with correlation (eta > 0) and speed-dependent shift, against HAPI.

The NIST parameters of the 30012 band have eta = 0 and SD_delta = 0, so hapi_reference.py never
exercises the eta C2 B term of the pCqSDHC denominator or Delta2. This script does, on the R(16)e
parameters of hapi_parameters.csv with eta and Delta2 set by hand, and checks each case twice:
HAPI's pcqsdhc with scipy's wofz (as the cpf=wofz rows of hapi_reference.py), and an independent
quadrature over the Maxwell speed distribution that uses no complex probability function
(Ngo et al. 2013, JQSRT 129, 89, eqs. 9-12: with C(x) = C0 + C2 (x^2 - 3/2) and
w(x) = (1 - eta) C(x) + nuVC - i(nu - nu0),
    A = < 1/(w - i k.v) >,  B = < x^2/(w - i k.v) >,
    I = (1/pi) A / (1 - (nuVC - eta (C0 - 3 C2/2)) A + eta C2 B),
the direction average in closed form, arctan(a x / w)/(a x)).

Writes OUT_DIR/hapi_correlated.csv:
    case,p_atm,nu0,gamma_d,gamma0,gamma2,delta0,delta2,nu_vc,eta,nu_cm1,re,im
(re, im from HAPI with wofz) and prints the largest HAPI-quadrature difference per case.

Usage (as hapi_reference.py):
    /tmp/hapienv/bin/python validation/beyond_voigt/hapi_correlated.py validation/beyond_voigt
"""
import csv
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hapi_reference as R  # noqa: E402  (patches HAPI's cpf on demand)

# (name, p_atm row of hapi_parameters.csv, eta, Delta2/Delta0, nuVC factor)
CASES = [
    ("eta0.2_1atm", "1.0", 0.2, 0.0, 1.0),
    ("eta0.6_1atm_d2", "1.0", 0.6, 0.5, 1.0),
    ("eta0.3_0.2atm_d2", "0.2", 0.3, -0.3, 3.0),
    ("eta0.5_0.05atm", "0.05", 0.5, 0.2, 1.0),
]


def quadrature(P, grid, panels=160, order=24, xmax=8.0):
    """pCqSDHC by Gauss-Legendre over reduced speed x = v/v_p (module docstring)."""
    xg, wg = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, xmax, panels + 1)
    lo, hi = edges[:-1, None], edges[1:, None]
    x = (lo + (hi - lo) * (xg + 1.0) / 2.0).ravel()
    wt = ((hi - lo) / 2.0 * wg).ravel() * 4.0 / math.sqrt(math.pi) * x**2 * np.exp(-x**2)
    a_d = P["gamma_d"] / math.sqrt(math.log(2.0))
    c0 = P["gamma0"] + 1j * P["delta0"]
    c2 = P["gamma2"] + 1j * P["delta2"]
    eta, nvc = P["eta"], P["nu_vc"]
    cx = c0 + c2 * (x**2 - 1.5)
    out = np.empty(len(grid), dtype=complex)
    for i in range(0, len(grid), 200):
        w = (1.0 - eta) * cx[None, :] + nvc - 1j * (grid[i:i + 200, None] - P["nu0"])
        ax = a_d * x[None, :]
        g = np.arctan(ax / w) / ax
        A = g @ wt
        B = g @ (wt * x**2)
        out[i:i + 200] = A / (1.0 - (nvc - eta * (c0 - 1.5 * c2)) * A + eta * c2 * B) / math.pi
    return out


def main(out_dir):
    params = {}
    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "hapi_parameters.csv")) as f:
        for row in csv.DictReader(f):
            if row["line"] == "R16e" and row["x_self"] == "0.0":
                params[row["p_atm"]] = {k: float(v) for k, v in row.items() if k not in ("line",)}
    rows = []
    for name, p, eta, d2_ratio, vc_factor in CASES:
        P = dict(params[p])
        P["eta"] = eta
        P["delta2"] = d2_ratio * P["delta0"]
        P["nu_vc"] = vc_factor * P["nu_vc"]
        grid = R.make_grid(P["nu0"])
        args = (P["nu0"], P["gamma_d"], P["gamma0"], P["gamma2"], P["delta0"], P["delta2"],
                P["nu_vc"], P["eta"])
        with R.use_cpf("wofz"):
            re, im = R.evaluate(args, grid, name)
        q = quadrature(P, grid)
        peak = np.max(re)
        print(f"{name}: HAPI(wofz) vs quadrature max |diff| {np.max(np.abs(re + 1j * im - q)) / peak:.2e}"
              " of the peak")
        for nu, r, m in zip(grid, re, im):
            rows.append([name, p, P["nu0"], P["gamma_d"], P["gamma0"], P["gamma2"], P["delta0"],
                         P["delta2"], P["nu_vc"], eta, "%.6f" % nu, repr(float(r)), repr(float(m))])
    with open(os.path.join(out_dir, "hapi_correlated.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "p_atm", "nu0", "gamma_d", "gamma0", "gamma2", "delta0", "delta2",
                    "nu_vc", "eta", "nu_cm1", "re", "im"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
