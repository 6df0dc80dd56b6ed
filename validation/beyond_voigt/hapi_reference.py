"""Reference line shapes beyond Voigt (HT, SDV, Voigt) for CO2 at 1.6 um, computed with HAPI.

Writes, into OUT_DIR:
  hapi_reference.csv   line,p_atm,t_k,x_self,profile,cpf,nu_cm1,re,im
  hapi_parameters.csv  line,p_atm,t_k,x_self,nu0,gamma_d,gamma0,gamma2,delta0,delta2,nu_vc,eta,y
and prints a summary (HAPI version, HAPI-cpf vs wofz differences, normalisation, issue #32 check).

Usage (from the project root; HAPI = PyPI `hitran-api`, plus numpy and scipy):
    python3 -m venv /tmp/hapienv && /tmp/hapienv/bin/pip install hitran-api numpy scipy
    /tmp/hapienv/bin/python validation/beyond_voigt/hapi_reference.py ../shared validation/beyond_voigt

What is computed
----------------
Lines R(16)e, R(26)e, P(20)e of CO2 626 30012<-00001 from
SHARED_DIR/data/nist_30012/CO2_30012_NIST_SDNGP_LM.csv (NIST/MATS speed-dependent Nelkin-Ghatak
parameters, plus first-order line mixing y for R(16)e; see PROVENANCE.md beside it).

Every line-shape value comes from HAPI's own pCqSDHC routine (`pcqsdhc`, which PROFILE_HT,
PROFILE_SDVOIGT and PROFILE_VOIGT wrap). HAPI 1.3's PROFILE_* functions return only the real part,
so the script calls `pcqsdhc` for (re, im) and checks that PROFILE_* returns exactly the same real
part (and re + Y*im when YRosen = Y is passed).

re/im are the real and imaginary parts of the *complex* normalised profile, with Y = 0. The
absorption profile with first-order line mixing is re + Y*im (Y in hapi_parameters.csv).
Sign: HAPI's complex profile has the Lorentz limit (1/pi)/(Gamma0 - i(nu - nu0 - Delta0)), so
im > 0 on the high-wavenumber side and Y > 0 raises that side (checked at run time).

Each profile is computed twice: cpf=hapi uses HAPI's own complex probability function
(VARIABLES['CPF'] = hum1_wei, Humlicek region 1 / Weideman N=24, and, inside pcqsdhc's main
branch, the 15-term asymptotic series `cpf3` where the two arguments straddle |z| = 8);
cpf=wofz replaces *both* by scipy.special.wofz (Faddeeva w(z), ~1e-13 relative), so the wofz rows
are HAPI's algorithm with an accurate w(z). The patch is verified (call counters, and the patched
Voigt against a closed-form Voigt written directly with wofz). The wofz rows are further checked
against an independent quadrature over the Maxwell speed distribution (speed_average_profile),
which uses no complex probability function at all.

Grid: nu0 +- 1.5 cm-1 in steps of 0.01 cm-1 (301 points a block, about 2 MB in all).

Parameter conventions (HITRAN, Tennyson et al. 2014, T_ref = 296 K, p in atm, x = CO2 mole
fraction, every parameter weighted (1-x)*P_air + x*P_self):
  Gamma0 = p * sum_b x_b gamma0_b (296/T)^n_gamma0_b
  Delta0 = p * sum_b x_b (delta0_b + n_delta0_b (T-296))
  Gamma2 = p * sum_b x_b SD_gamma_b gamma0_b (296/T)^n_gamma2_b        (SD_gamma = Gamma2/Gamma0 at 296 K)
  Delta2 = p * sum_b x_b SD_delta_b (delta0_b + n_delta0_b (T-296))   (SD_delta = 0 in this file; choice noted)
  nuVC   = p * sum_b x_b nuVC_b (296/T)^n_nuVC_b
  eta    = sum_b x_b eta_b                                            (0 here)
  Y      = p * sum_b x_b y_b (296/T)^n_y_b
  gamma_D: HAPI's own calculate_parameter_GammaD (HAPI's molecularMass(2,1) = 43.98983 g/mol,
           its constants cBolts = 1.380648813e-16 erg/K, cc = 2.99792458e10 cm/s,
           amu = 1.66053873e-27 kg).

HAPI issue #32 (hitranonline/hapi): in one vectorised pcqsdhc call, when some points fall in its
near-centre branch (PART2, |X| <= 3e-8 |Y|, only at very low pressure) and others in the main
branch (PART4), the PART4 code indexes full-length arrays with subset masks and raises IndexError
(or, with old numpy, mixes values). The script evaluates vectorised, falls back to point-by-point
evaluation if a call raises or gives non-finite values, and re-evaluates every cpf=hapi block point
by point to prove the vectorised values are unaffected at the states used here. It also reproduces
the failure at p = 1e-5 atm as a demonstration (not written to the CSV).
"""
import contextlib
import csv
import importlib
import io
import math
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402
from scipy.special import wofz  # noqa: E402

with contextlib.redirect_stdout(io.StringIO()):  # HAPI prints a banner on import
    import hapi  # noqa: E402
# The PyPI package is a folder `hapi/` whose __init__ does `from .hapi import *`; pcqsdhc looks
# up VARIABLES['CPF'] and cpf3 in the globals of the module that defines it, so patch that one.
H = importlib.import_module("hapi.hapi") if hasattr(hapi, "__path__") else hapi

T_REF = 296.0
STEP = 0.01           # grid step [cm-1]: 301 points a block keep the committed CSV near 2 MB
HALF_WIDTH = 1.5      # grid half-width around nu0 [cm-1]
LINES = ["R16e", "R26e", "P20e"]   # local_lower_quanta without blanks
# (p [atm], T [K], x_self): four air-broadened states and the Mendonca et al. measurement
# (742.08 Torr, 22.15 degC, 9.03 % CO2 in air).
STATES = [
    (1.0, 296.0, 0.0),
    (0.5, 260.0, 0.0),
    (0.2, 230.0, 0.0),
    (0.05, 210.0, 0.0),
    (742.08 / 760.0, 295.3, 0.0903),
]
PROFILES = ["ht", "sdvoigt", "voigt"]
CPFS = ["hapi", "wofz"]


# --------------------------------------------------------------------------- line data
def read_lines(path):
    """Rows of the NIST csv keyed by compact quanta ('R16e'); numeric fields as float."""
    out = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):      # the file has 'elower' twice (same value): harmless
            key = row["local_lower_quanta"].replace(" ", "")
            rec = {}
            for k, v in row.items():
                try:
                    rec[k] = float(v)
                except (TypeError, ValueError):
                    rec[k] = v
            out[key] = rec
    return out


def line_parameters(rec, p, t, x):
    """Profile parameters of one line at (p [atm], T [K], CO2 mole fraction x), HITRAN conventions."""
    frac = {"air": 1.0 - x, "self": x}
    g0 = d0 = g2 = d2 = nvc = eta = y = 0.0
    for b, xb in frac.items():
        if xb == 0.0:
            continue
        gam0_b = rec[f"gamma0_{b}"] * (T_REF / t) ** rec[f"n_gamma0_{b}"]
        del0_b = rec[f"delta0_{b}"] + rec[f"n_delta0_{b}"] * (t - T_REF)
        g0 += xb * gam0_b
        d0 += xb * del0_b
        # SD_gamma is Gamma2/Gamma0 at 296 K; Gamma2 scales with its own exponent n_gamma2.
        g2 += xb * rec[f"SD_gamma_{b}"] * rec[f"gamma0_{b}"] * (T_REF / t) ** rec[f"n_gamma2_{b}"]
        # SD_delta is Delta2/Delta0; chosen to follow Delta0's linear T law (SD_delta = 0 here).
        d2 += xb * rec[f"SD_delta_{b}"] * del0_b
        nvc += xb * rec[f"nuVC_{b}"] * (T_REF / t) ** rec[f"n_nuVC_{b}"]
        eta += xb * rec[f"eta_{b}"]
        y += xb * rec[f"y_{b}"] * (T_REF / t) ** rec[f"n_y_{b}"]
    # Doppler HWHM from HAPI's own routine (its molecular mass and constants).
    trans = {"Diluent": {"air": 1.0}, "T": t, "p": p, "molec_id": int(rec["molec_id"]),
             "local_iso_id": int(rec["local_iso_id"]), "nu": rec["nu"]}
    gamma_d = H.calculate_parameter_GammaD(None, trans)
    return {"nu0": rec["nu"], "gamma_d": float(gamma_d), "gamma0": p * g0, "gamma2": p * g2,
            "delta0": p * d0, "delta2": p * d2, "nu_vc": p * nvc, "eta": eta, "y": p * y}


def gamma_d_textbook(nu0, t):
    """Doppler HWHM with CODATA 2018 constants and m = 43.98983 u (for comparison only)."""
    k, c, u = 1.380649e-23, 299792458.0, 1.66053906660e-27
    return nu0 / c * math.sqrt(2.0 * k * t * math.log(2.0) / (43.98983 * u))


# --------------------------------------------------------------------------- cpf switching
CALLS = {"CPF": 0, "cpf3": 0, "wofz": 0}
HAPI_CPF = H.VARIABLES["CPF"]
HAPI_CPF3 = H.cpf3


def _counted(fn, name):
    def wrapper(x, y, *args):
        CALLS[name] += np.size(x)
        return fn(x, y, *args)
    return wrapper


def cpf_wofz(x, y, *_):
    """Drop-in for HAPI's cpf signature: (Re w, Im w) of w(x + iy) by scipy.special.wofz."""
    CALLS["wofz"] += np.size(x)
    w = wofz(np.asarray(x, dtype=float) + 1j * np.asarray(y, dtype=float))
    return w.real, w.imag


@contextlib.contextmanager
def use_cpf(name):
    """Make pcqsdhc use HAPI's own cpf ('hapi', call-counted) or scipy's wofz ('wofz')."""
    if name == "hapi":
        H.VARIABLES["CPF"], H.cpf3 = _counted(HAPI_CPF, "CPF"), _counted(HAPI_CPF3, "cpf3")
    else:
        H.VARIABLES["CPF"], H.cpf3 = cpf_wofz, cpf_wofz
    try:
        yield
    finally:
        H.VARIABLES["CPF"], H.cpf3 = HAPI_CPF, HAPI_CPF3


# --------------------------------------------------------------------------- profiles
def profile_args(prof, P):
    """pcqsdhc arguments (sg0, GamD, Gam0, Gam2, Shift0, Shift2, anuVC, eta) for a profile."""
    if prof == "ht":
        return (P["nu0"], P["gamma_d"], P["gamma0"], P["gamma2"], P["delta0"], P["delta2"],
                P["nu_vc"], P["eta"])
    if prof == "sdvoigt":
        return (P["nu0"], P["gamma_d"], P["gamma0"], P["gamma2"], P["delta0"], P["delta2"], 0.0, 0.0)
    return (P["nu0"], P["gamma_d"], P["gamma0"], 0.0, P["delta0"], 0.0, 0.0, 0.0)


def hapi_profile_real(prof, a, grid, y=0.0):
    """The same profile through HAPI's public PROFILE_* wrappers (real part only in HAPI 1.3)."""
    nu0, gd, g0, g2, d0, d2, nvc, eta = a
    if prof == "ht":
        return H.PROFILE_HT(nu0, gd, g0, g2, d0, d2, nvc, eta, grid, YRosen=y)
    if prof == "sdvoigt":
        return H.PROFILE_SDVOIGT(nu0, gd, g0, g2, d0, d2, grid, YRosen=y)
    return H.PROFILE_VOIGT(nu0, gd, g0, d0, grid, YRosen=y)


def pointwise(a, grid):
    """pcqsdhc one point at a time (immune to HAPI issue #32)."""
    re, im = np.empty(len(grid)), np.empty(len(grid))
    for i, s in enumerate(grid):
        r, m = H.pcqsdhc(*a, np.array([s]))
        re[i], im[i] = r[0], m[0]
    return re, im


FALLBACKS = []


def evaluate(a, grid, tag):
    """Vectorised pcqsdhc; point by point if the call raises or returns non-finite values."""
    try:
        re, im = H.pcqsdhc(*a, grid)
        if np.all(np.isfinite(re)) and np.all(np.isfinite(im)):
            return np.asarray(re, float), np.asarray(im, float)
        FALLBACKS.append((tag, "non-finite"))
    except (IndexError, ValueError) as e:
        FALLBACKS.append((tag, f"{type(e).__name__}: {e}"))
    return pointwise(a, grid)


def make_grid(nu0):
    """nu0 +- HALF_WIDTH in STEP, each value the float of its 6-decimal text (as written)."""
    n = int(round(HALF_WIDTH / STEP))
    return np.array([float("%.6f" % (nu0 + k * STEP)) for k in range(-n, n + 1)])


def wide_grid(nu0, core=2.0, h=2.5e-4, far=1.0e5, n_log=6000):
    """Integration grid: uniform core |u| <= core, then log-spaced wings to |u| = far."""
    core_u = np.arange(-core, core + h / 2, h)
    s = np.linspace(math.log(core), math.log(far), n_log)
    return nu0 + core_u, nu0 + np.exp(s), nu0 - np.exp(s), s


def area(prof, a, nu0, gamma0):
    """Integral of re over nu by trapezoid (uniform core + log-variable wings) + analytic tail."""
    core, right, left, s = wide_grid(nu0)
    f_core = evaluate(a, core, "area")[0]
    f_r = evaluate(a, right, "area")[0]
    f_l = evaluate(a, left, "area")[0]
    u = np.exp(s)
    total = np.trapezoid(f_core, core) + np.trapezoid(f_r * u, s) + np.trapezoid(f_l * u, s)
    tail = 2.0 * gamma0 / (math.pi * u[-1])       # Lorentz wings beyond |u| = 1e5 cm-1
    return total, total + tail


# --------------------------------------------------------------------------- independent reference
def speed_average_profile(prof, P, grid, panels=120, order=20, xmax=8.0):
    """The same complex profile by direct quadrature over the Maxwell speed distribution (eta = 0).

    With reduced speed x = v/v_p (v_p most probable speed), a = gamma_D/sqrt(ln 2) the 1/e Doppler
    half-width and C(x) = Gamma0 + i Delta0 + (Gamma2 + i Delta2)(x^2 - 3/2) (quadratic speed
    dependence), the average of 1/(C(x) + nuVC - i(nu - nu0 - a x mu)) over directions mu in
    [-1, 1] is arctan(a x / w)/(a x), w = C(x) + nuVC - i(nu - nu0). Then
        A(nu) = int_0^inf (4/sqrt(pi)) x^2 exp(-x^2) arctan(a x / w)/(a x) dx
    and the hard-collision (Rautian-type) profile is (1/pi) A/(1 - nuVC A) (Ngo et al. 2013, eta=0).
    Composite Gauss-Legendre in x on [0, 8]. Independent of any complex probability function.
    """
    xg, wg = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, xmax, panels + 1)
    lo, hi = edges[:-1, None], edges[1:, None]
    x = (lo + (hi - lo) * (xg + 1.0) / 2.0).ravel()
    wt = ((hi - lo) / 2.0 * wg).ravel() * 4.0 / math.sqrt(math.pi) * x**2 * np.exp(-x**2)
    a_d = P["gamma_d"] / math.sqrt(math.log(2.0))
    g2, d2, nvc = P["gamma2"], P["delta2"], P["nu_vc"]
    if prof == "sdvoigt":
        nvc = 0.0
    elif prof == "voigt":
        g2 = d2 = nvc = 0.0
    c = P["gamma0"] + g2 * (x**2 - 1.5) + 1j * (P["delta0"] + d2 * (x**2 - 1.5)) + nvc
    out = np.empty(len(grid), dtype=complex)
    for i in range(0, len(grid), 200):          # chunks keep the (grid x nodes) array small
        w = c[None, :] - 1j * (grid[i:i + 200, None] - P["nu0"])
        ax = a_d * x[None, :]
        amp = (np.arctan(ax / w) / ax) @ wt
        out[i:i + 200] = amp / (1.0 - nvc * amp) / math.pi
    return out


# --------------------------------------------------------------------------- checks
def check_wofz_patch():
    """The patch is live: counters move and patched Voigt == closed-form wofz Voigt."""
    nu0, gd, g0, d0 = 6359.967248, 0.00966, 0.0739, -0.0054
    grid = nu0 + np.linspace(-1.5, 1.5, 301)
    CALLS.update({"CPF": 0, "cpf3": 0, "wofz": 0})
    with use_cpf("wofz"):
        re_w, im_w = H.pcqsdhc(nu0, gd, g0, 0.0, d0, 0.0, 0.0, 0.0, grid)
    assert CALLS["wofz"] > 0 and CALLS["CPF"] == 0
    with use_cpf("hapi"):
        re_h, _ = H.pcqsdhc(nu0, gd, g0, 0.0, d0, 0.0, 0.0, 0.0, grid)
    assert CALLS["CPF"] > 0
    assert H.VARIABLES["CPF"] is HAPI_CPF and H.cpf3 is HAPI_CPF3   # restored
    c = math.sqrt(math.log(2.0)) / gd
    w = wofz(((grid - nu0 - d0) + 1j * g0) * c)
    ref = c / math.sqrt(math.pi) * w                  # (1/pi) * sqrt(pi)*cte*w(z)
    err_w = max(np.max(np.abs(re_w - ref.real)), np.max(np.abs(im_w - ref.imag))) / ref.real.max()
    err_h = np.max(np.abs(re_h - ref.real)) / ref.real.max()
    assert err_w < 1e-12, err_w
    assert err_h > 0.0                                 # HAPI's cpf really differs from wofz
    return err_w, err_h


def check_sign():
    """Im > 0 above the shifted centre, < 0 below, and PROFILE_LORENTZ-like Lorentz limit."""
    nu0, g0, d0 = 6359.967248, 0.07, -0.005
    grid = np.array([nu0 + d0 - 1.0, nu0 + d0 + 1.0])
    re, im = H.pcqsdhc(nu0, 1e-6, g0, 0.0, d0, 0.0, 0.0, 0.0, grid)   # ~Lorentz (tiny gamma_D)
    lor = (1.0 / math.pi) / (g0 - 1j * (grid - nu0 - d0))
    assert im[0] < 0 < im[1]
    assert np.allclose(re, lor.real, rtol=1e-6) and np.allclose(im, lor.imag, rtol=1e-6)
    return im


def issue32_demo(rec):
    """Reproduce HAPI issue #32 (IndexError at p = 1e-5 atm, SDV) and show point-by-point works."""
    P = line_parameters(rec, 1.0e-5, 296.0, 0.0)
    a = profile_args("sdvoigt", P)
    grid = make_grid(P["nu0"])
    try:
        H.pcqsdhc(*a, grid)
        vec = "vectorised call ran"
    except IndexError as e:
        vec = f"vectorised call raised IndexError ({e})"
    re, _ = pointwise(a, grid)
    return vec, bool(np.all(np.isfinite(re))), float(re.max())


# --------------------------------------------------------------------------- main
def fmt_state(p, t, x):
    return f"p={p:.4f} atm T={t:g} K x={x:g}"


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: hapi_reference.py SHARED_DIR OUT_DIR")
    shared, out_dir = sys.argv[1], sys.argv[2]
    os.makedirs(out_dir, exist_ok=True)
    t_start = time.perf_counter()
    data = read_lines(os.path.join(shared, "data", "nist_30012", "CO2_30012_NIST_SDNGP_LM.csv"))

    print(f"HAPI version {H.HAPI_VERSION} ({H.__file__}); numpy {np.__version__}")
    print(f"HAPI cpf: VARIABLES['CPF'] = {HAPI_CPF.__name__}; pcqsdhc's PART4 also calls cpf3")
    err_w, err_h = check_wofz_patch()
    print(f"wofz patch: patched HAPI Voigt vs closed-form wofz Voigt {err_w:.1e} of peak; "
          f"HAPI's own cpf vs wofz {err_h:.1e} of peak")
    im = check_sign()
    print(f"sign: Im at nu0+D0-1, nu0+D0+1 = {im[0]:+.4e}, {im[1]:+.4e} "
          "(Lorentz limit (1/pi)/(G0 - i(nu-nu0-D0)); Y>0 raises the high-wavenumber side)")

    param_rows, csv_rows, summary, areas = [], [], {}, []
    pw_max = 0.0
    indep = {}          # profile -> [max |wofz - speed quadrature|/peak, max local rel. (re)]
    local = {}          # (state, profile group) -> max |hapi - wofz| / |wofz| for re
    cpf3_points = {}
    for name in LINES:
        rec = data[name]
        grid = make_grid(rec["nu"])
        for (p, t, x) in STATES:
            P = line_parameters(rec, p, t, x)
            param_rows.append([name, p, t, x] + [P[k] for k in
                              ("nu0", "gamma_d", "gamma0", "gamma2", "delta0", "delta2",
                               "nu_vc", "eta", "y")])
            for prof in PROFILES:
                a = profile_args(prof, P)
                res = {}
                for cpf in CPFS:
                    CALLS.update({"CPF": 0, "cpf3": 0, "wofz": 0})
                    with use_cpf(cpf):
                        re, im = evaluate(a, grid, (name, p, t, x, prof, cpf))
                        # HAPI's public wrapper must give the same real part, and re + Y*im with Y.
                        assert np.array_equal(hapi_profile_real(prof, a, grid), re)
                        if P["y"] != 0.0:
                            assert np.allclose(hapi_profile_real(prof, a, grid, P["y"]),
                                               re + P["y"] * im, rtol=1e-14, atol=0.0)
                        if cpf == "hapi":
                            cpf3_points[(name, p, prof)] = CALLS["cpf3"]
                            # issue #32 check: point-by-point must equal vectorised exactly.
                            re_p, im_p = pointwise(a, grid)
                            pw_max = max(pw_max, np.max(np.abs(re_p - re)), np.max(np.abs(im_p - im)))
                        else:
                            assert CALLS["wofz"] > 0 and CALLS["CPF"] == CALLS["cpf3"] == 0
                            ref = speed_average_profile(prof, P, grid)
                            pk = ref.real.max()
                            e = indep.setdefault(prof, [0.0, 0.0])
                            e[0] = max(e[0], np.max(np.abs(re - ref.real)) / pk,
                                       np.max(np.abs(im - ref.imag)) / pk)
                            e[1] = max(e[1], np.max(np.abs(re - ref.real) / np.abs(ref.real)))
                        areas.append((name, (p, t, x), prof, cpf) +
                                     area(prof, a, P["nu0"], P["gamma0"]))
                    res[cpf] = (re, im)
                    for nu, r, m in zip(grid, re, im):
                        csv_rows.append((name, p, t, x, prof, cpf, nu, r, m))
                peak = res["wofz"][0].max()
                d_re = np.max(np.abs(res["hapi"][0] - res["wofz"][0])) / peak
                d_im = np.max(np.abs(res["hapi"][1] - res["wofz"][1])) / peak
                s = summary.setdefault((p, t, x), [0.0, 0.0])
                s[0], s[1] = max(s[0], d_re), max(s[1], d_im)
                grp = "voigt" if prof == "voigt" else "ht/sdvoigt"
                lr = np.max(np.abs(res["hapi"][0] - res["wofz"][0]) / np.abs(res["wofz"][0]))
                local[((p, t, x), grp)] = max(local.get(((p, t, x), grp), 0.0), lr)

    # ---- write CSVs
    with open(os.path.join(out_dir, "hapi_parameters.csv"), "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["line", "p_atm", "t_k", "x_self", "nu0", "gamma_d", "gamma0", "gamma2",
                    "delta0", "delta2", "nu_vc", "eta", "y"])
        for row in param_rows:
            w.writerow([row[0]] + [repr(float(v)) for v in row[1:]])
    with open(os.path.join(out_dir, "hapi_reference.csv"), "w") as f:
        f.write("line,p_atm,t_k,x_self,profile,cpf,nu_cm1,re,im\n")
        for (name, p, t, x, prof, cpf, nu, r, m) in csv_rows:
            # nu: its 6-decimal text is exactly the value used; re/im: 12 significant digits.
            f.write(f"{name},{p!r},{t!r},{x!r},{prof},{cpf},{nu:.6f},{r:.11e},{m:.11e}\n")

    # ---- summary
    print("\nHAPI cpf vs wofz, max |hapi - wofz| / peak(re) over lines and profiles:")
    for (p, t, x), (dr, di) in summary.items():
        print(f"  {fmt_state(p, t, x)}: re {dr:.2e}, im {di:.2e}")
    print("  max local |hapi - wofz| / |wofz| of re (wings, grid +-1.5 cm-1):")
    for ((p, t, x), grp), v in local.items():
        print(f"    {fmt_state(p, t, x)} {grp}: {v:.2e}")
    print("\ncpf=wofz rows vs independent speed-quadrature profile (no cpf at all):")
    for prof, (e_pk, e_loc) in indep.items():
        print(f"  {prof:7s}: max |diff| / peak {e_pk:.1e} (re and im), max local rel. (re) {e_loc:.1e}")
    print("\nNormalisation, integral of re over nu (trapezoid to |nu-nu0| = 1e5 cm-1; "
          "+ Lorentz tail 2*G0/(pi*1e5)):")
    for prof in PROFILES:
        for cpf in CPFS:
            v = [wt for (_, _, pr, cp, _, wt) in areas if pr == prof and cp == cpf]
            print(f"  {prof:7s} cpf={cpf:4s}: integral - 1 in [{min(v) - 1:+.1e}, {max(v) - 1:+.1e}]"
                  f" over {len(v)} line/state pairs")
    n_cpf3 = sum(1 for v in cpf3_points.values() if v)
    print(f"\npcqsdhc's cpf3 branch used in {n_cpf3} of {len(cpf3_points)} cpf=hapi blocks: "
          + ", ".join(f"{k[0]} p={k[1]:.4g} {k[2]} ({v} w evaluations)" for k, v in cpf3_points.items() if v))
    print(f"issue #32: fallbacks to point-by-point {len(FALLBACKS)}; "
          f"max |vectorised - point-by-point| (cpf=hapi) = {pw_max:.1e}")
    for fb in FALLBACKS:
        print("  fallback:", fb)
    vec, ok, pk = issue32_demo(data["R16e"])
    print(f"issue #32 demo (R16e, SDV, p = 1e-5 atm, 296 K): {vec}; point by point finite={ok}, "
          f"peak {pk:.4g}")
    gd = [(r[0], r[1], r[2], r[5], gamma_d_textbook(r[4], r[2])) for r in param_rows]
    rel = max(abs(g / tb - 1.0) for *_, g, tb in gd)
    print(f"gamma_D: HAPI vs CODATA-2018 textbook formula (m = 43.98983 u): max rel. diff {rel:.1e}")
    size = os.path.getsize(os.path.join(out_dir, "hapi_reference.csv"))
    print(f"\n{len(csv_rows)} rows, {size / 1e6:.2f} MB; total time {time.perf_counter() - t_start:.1f} s")


if __name__ == "__main__":
    main()
