#!/usr/bin/env python3
"""Writes the lidarsim scenes of the multiscatter Jacobian comparison (c1_per_gate.toml,
calipso_like.toml) and the two phase tables of the CALIPSO-like case, from cases.py.

    /work/venv/bin/python validation/jacobians/make_scenes.py

Every cloud gate is its own [[layer]], so that lidarsim's per-layer Jacobian is a per-gate one,
as multiscatter's is.

Phase tables of the CALIPSO-like case. multiscatter knows a particle only by its extinction,
equivalent-area radius a, lidar ratio S, single-scattering albedo and asymmetry factor g. Its
small-angle part (Hogan 2008, "Fast lidar and radar multiple-scattering models. Part I", J. Atmos.
Sci. 65, 3621-3635) puts half of the extinction into a Gaussian forward lobe of 1/e half-width
Theta = lambda / (pi a) (src/fast_small_angle.c), and its wide-angle part (Hogan & Battaglia 2008,
"Fast lidar and radar multiple-scattering models. Part II: Wide-angle scattering using the
time-dependent two-stream approximation", J. Atmos. Sci. 65, 3636-3651) scatters the other half
with asymmetry 2g - 1 (src/wide_angle.c, g_equiv for ssa = 1). The tables written here are that
phase function, so that the two models get the same particles and differ only by transport:

    P = 0.5 * lobe(theta; Theta) + 0.5 * W,   W = f HG(g1) + (1 - f) HG(-0.7)

with f and g1 chosen so that W has asymmetry 2g - 1 and P(180) = 4 pi / S (S = 20 sr; the
backward HG term supplies the backscatter that a lidar ratio of 20 sr needs). The table is then
normalised with lidarsim's own rule (linear in cos theta between nodes, src/particles/table.rs),
and its S and g recomputed with that rule are what run_multiscatter.py gives multiscatter.
"""
import math
import os

import numpy as np

from cases import CASES, gate_centres, layer_name

HERE = os.path.dirname(os.path.abspath(__file__))
G2 = -0.7


def hg(g, mu):
    return (1 - g * g) / (1 + g * g - 2 * g * mu) ** 1.5


def norm(theta_deg, p):
    """(1/4pi) integral of P over the sphere, P linear in mu between nodes (lidarsim's rule)."""
    mu = np.cos(np.radians(theta_deg))
    return 0.5 * np.sum(0.5 * (p[1:] + p[:-1]) * (mu[:-1] - mu[1:]))


def asym(theta_deg, p):
    """<cos theta>, exact for P linear in mu between nodes."""
    mu = np.cos(np.radians(theta_deg))
    a, b = mu[:-1], mu[1:]
    pa, pb = p[:-1], p[1:]
    # integral over [b, a] of (pb + (pa - pb)(mu - b)/(a - b)) mu dmu
    s = (a - b)
    integ = pb * (a * a - b * b) / 2 + (pa - pb) / s * ((a**3 - b**3) / 3 - b * (a * a - b * b) / 2)
    return 0.5 * np.sum(integ) / norm(theta_deg, p)


def grid():
    # fine near 0 (the ice lobe is 0.19 deg wide) and near 180 (the backscatter value)
    return np.unique(np.concatenate([
        np.arange(0.0, 2.0, 0.002), np.arange(2.0, 20.0, 0.02), np.arange(20.0, 179.0, 0.25),
        np.arange(179.0, 180.0, 0.01), [180.0]]).round(6))


def hogan_phase(wavelength_m, radius_m, S, g):
    th = grid()
    t = np.radians(th)
    mu = np.cos(t)
    big = 1.0 / (wavelength_m / (math.pi * radius_m))
    lobe = np.exp(-(t * big) ** 2)
    lobe /= norm(th, lobe)
    gw = 2 * g - 1
    want180 = 2 * (4 * math.pi / S) - 0.0  # W(180) such that 0.5 W(180) = 4 pi / S
    # solve f, g1: f g1 + (1 - f) G2 = gw ; f HG(g1, -1) + (1 - f) HG(G2, -1) = want180
    g1 = gw
    for _ in range(200):
        f = (hg(G2, -1.0) - want180) / (hg(G2, -1.0) - hg(g1, -1.0))
        g1 = (gw - (1 - f) * G2) / f
    w = f * hg(g1, mu) + (1 - f) * hg(G2, mu)
    w /= norm(th, w)
    p = 0.5 * lobe + 0.5 * w
    p /= norm(th, p)
    return th, p, dict(f=f, g1=g1, theta_lobe_rad=1 / big)


def write_phase(name, case_wl, radius_m, S_nominal, g_nominal, label):
    th, p, info = hogan_phase(case_wl, radius_m, S_nominal, g_nominal)
    S = 4 * math.pi / p[-1]
    g = asym(th, p)
    with open(os.path.join(HERE, name), "w") as f:
        f.write("# lidarsim phase function table\n")
        f.write(f"# wavelength_nm = {case_wl * 1e9:g}\n")
        f.write("# refractive_index = none\n")
        f.write(f"# distribution = none: {label}, Hogan-model phase function (make_scenes.py): "
                f"0.5 Gaussian forward lobe of 1/e half-width lambda/(pi a) = {info['theta_lobe_rad'] * 1e3:.4f} mrad "
                f"(a = {radius_m * 1e6:g} um) + 0.5 [{info['f']:.6f} HG({info['g1']:.6f}) + {1 - info['f']:.6f} HG({G2})]\n")
        f.write(f"# source = validation/jacobians/make_scenes.py (issue 40, item 2(c))\n")
        f.write("# single_scattering_albedo = 1\n")
        f.write(f"# asymmetry = {g:.6f}\n")
        f.write(f"# lidar_ratio_sr = {S:.6f}\n")
        f.write("theta_deg,phase_4pi\n")
        for a, b in zip(th, p):
            f.write(f"{a:.4f},{b:.9e}\n")
    return S, g


def read_table_meta(path):
    meta = {}
    for line in open(path):
        if line.startswith("#") and "=" in line:
            k, v = line[1:].split("=", 1)
            meta[k.strip()] = v.strip()
    return meta


def lidar_block(c, description):
    out = [f'description = "{description}"', "", "[lidar]"]
    if c["lidar_altitude_m"] >= 1000:
        out.append(f"altitude_km = {c['lidar_altitude_m'] / 1000:g}")
    else:
        out.append(f"altitude_m = {c['lidar_altitude_m']:g}")
    out += [
        f"zenith_angle_deg = {0.0 if c['looking_up'] else 180.0}",
        f"pulse_energy_j = {c['pulse_energy_j']}",
        f"beam_divergence_full_angle_mrad = {c['beam_full_angle_mrad']}",
    ]
    if c["beam_full_angle_mrad"] > 0:
        out.append('beam_profile = "gaussian"')
    out += [
        f"telescope_diameter_m = {c['telescope_diameter_m']}",
        f"optical_efficiency = {c['optical_efficiency']}",
        "fov_full_angle_mrad = [" + ", ".join(f"{v:g}" for v in c["fov_full_angle_mrad"]) + "]",
        "", "[[channel]]", f'name = "{c["wavelength_m"] * 1e9:.0f}"',
        f"wavelength_nm = {c['wavelength_m'] * 1e9:.1f}", "", "[gates]",
    ]
    e = c["gate_edges_m"]
    if c["looking_up"]:
        r0, r1 = e[0] - c["lidar_altitude_m"], e[-1] - c["lidar_altitude_m"]
    else:
        r0, r1 = c["lidar_altitude_m"] - e[0], c["lidar_altitude_m"] - e[-1]
    out += [f"start_m = {r0:.1f}", f"end_m = {r1:.1f}", f"width_m = {abs(e[1] - e[0]):.1f}", ""]
    return out


def layer_lines(case, k, lo, hi, ext, ssa, phase):
    return ["[[layer]]", f'name = "{layer_name(case, k)}"', f"base_m = {lo:.1f}", f"top_m = {hi:.1f}",
            f"extinction_per_m = {ext:.9g}", f"single_scattering_albedo = {ssa}", f"phase = {phase}", ""]


def simulation_block(max_order):
    return ["[simulation]", "photons = 1000000", "seed = 1", f"max_order = {max_order}",
            "# Issue 40: per-layer Jacobians are not in lidarsim yet; the lead switches them on here.",
            "jacobians = true", ""]


def main():
    # C.1, one layer per 10 m gate of the cloud
    c = CASES["c1"]
    head = [
        "# Bissonnette et al. (1995), \"LIDAR multiple scattering from clouds\", Appl. Phys. B 60, 355-362,",
        "# case C.1 as scenes/bissonnette_c1.toml, with the cloud split into one [[layer]] per 10 m gate",
        "# so that lidarsim's per-layer Jacobian is per gate (issue 40, item 2(c): beside Hogan's",
        "# multiscatter -jacobian; validation/jacobians/README.md). Generated by make_scenes.py.",
    ]
    lines = head + lidar_block(c, "C.1 per gate: Bissonnette et al. (1995) C.1, one layer per 10 m gate")
    for k, (lo, hi, ext, ssa, g, a, S, drop, table) in enumerate(c["layers"]):
        lines += layer_lines("c1", k, lo, hi, ext, ssa, f'{{ kind = "table", file = "{table}" }}')
    lines += simulation_block(10)
    open(os.path.join(HERE, "c1_per_gate.toml"), "w").write("\n".join(lines))

    # CALIPSO-like: phase tables, then the scene
    c = CASES["calipso"]
    made = {}
    for name, a, label in [("hogan_ice_50um_532nm.txt", 50e-6, "ice, equivalent-area radius 50 um"),
                           ("hogan_liquid_10um_532nm.txt", 10e-6, "liquid, equivalent-area radius 10 um")]:
        made[name] = write_phase(name, c["wavelength_m"], a, 20.0, 0.85, label)
        print(f"{name}: lidar ratio {made[name][0]:.4f} sr, g {made[name][1]:.5f}")
    head = [
        "# CALIPSO-like case for issue 40, item 2(c) (validation/jacobians/README.md; cases.py says where",
        "# each number comes from): the profile of multiscatter's example hogan2008fig8.in (ice cloud",
        "# 4100-7100 m, 0.6 km^-1; liquid cloud 1100-2100 m, 3 km^-1; air 1.34e-5 exp(-z/8 km) m^-1) under",
        "# CALIOP's nominal geometry (Winker et al. 2009): 705 km, 532 nm, divergence 100 urad, FOV 130 urad.",
        "# Each cloud gate is its own [[layer]]; the air is one Rayleigh layer (no depolarisation, as",
        "# multiscatter's 3/(8 pi)) per 200 m gate, after the cloud layers. Phase tables: Hogan-model",
        "# phase functions (make_scenes.py). Generated by make_scenes.py.",
    ]
    lines = head + lidar_block(c, "CALIPSO-like: ice and liquid cloud under CALIOP, one layer per 200 m gate")
    for k, (lo, hi, ext, ssa, g, a, S, drop, table) in enumerate(c["layers"]):
        lines += layer_lines("calipso", k, lo, hi, ext, ssa, f'{{ kind = "table", file = "{table}" }}')
    e = c["gate_edges_m"]
    for j, zc in enumerate(gate_centres("calipso")):
        lo, hi = sorted((e[j], e[j + 1]))
        lines += ["[[layer]]", f'name = "air {lo:.0f}-{hi:.0f} m"', f"base_m = {lo:.1f}", f"top_m = {hi:.1f}",
                  f"extinction_per_m = {c['air'](zc):.9g}", "single_scattering_albedo = 1.0",
                  'phase = { kind = "rayleigh", depolarization_factor = 0.0 }', ""]
    lines += simulation_block(10)
    open(os.path.join(HERE, "calipso_like.toml"), "w").write("\n".join(lines))


if __name__ == "__main__":
    main()
