#!/usr/bin/env python3
"""Bissonnette et al. (1995) case C.1 with Hogan's fast multiple-scattering model "multiscatter"
(PVC small-angle method, Hogan 2008, J. Atmos. Sci. 65, 3621; TDTS wide-angle method, Hogan &
Battaglia 2008, J. Atmos. Sci. 65, 3636), for comparison with lidarsim's Monte Carlo.

multiscatter is not part of lidarsim and is not in this repository. Get version 1.2.x from
http://www.met.reading.ac.uk/clouds/multiscatter/ (or the copy of 1.2.10 in the public GitHub
repository mgrecu35/gmp_combined, Code/multiscatter-1.2.10), build it with `make` (gcc), and run

    python3 validation/c1_multiple_scattering/hogan_multiscatter.py PATH/TO/bin/multiscatter

It writes hogan_c1.csv beside this script: per 10 m gate (depth into the cloud) and field of view,
the ratio of multiscatter's total apparent backscatter to its own single-scattering one.

Inputs, as the C.1 scene (scenes/bissonnette_c1.toml) and the reference Mie optics
(../shared/reference/c1_summary.csv): 1064 nm, ground lidar, pencil beam (1e-9 rad), top-hat
fields of view 0.1 ... 10 mrad full angle (half-widths given), cloud 1000-1300 m of extinction
17.23 km^-1, lidar ratio 19.59 sr, single-scattering albedo 0.99991, g 0.8371, no air. The model
characterises the droplets by one radius (the width of the diffraction peak): the C.1 effective
radius, 6 um (the equivalent-area radius sqrt(<r^2>) is 5.0 um; run with RADIUS_UM=5.0 in the
environment to see the sensitivity). Gates of 1 m, averaged to the 10 m gates of the scene.
Droplet fraction 1: multiscatter's droplet shape of the phase function near 180 degrees.
"""
import os
import subprocess
import sys
import tempfile

import numpy as np

FOVS_MRAD = [0.1, 0.5, 1.0, 2.0, 5.0, 10.0]
EXT = 17.23e-3
S = 19.59
SSA = 0.9999076
G = 0.837121
RADIUS = float(os.environ.get("RADIUS_UM", "6.0")) * 1e-6
Z = np.arange(900.5, 1400.0, 1.0)


def profile():
    head = [len(Z), 1064e-9, 0.0, 1e-9] + [f * 0.5e-3 for f in FOVS_MRAD]
    lines = [" ".join(f"{v:.9g}" for v in head)]
    for z in Z:
        e = EXT if 1000.0 < z < 1300.0 else 0.0
        lines.append(f"{z:.1f} {e:.6g} {RADIUS:.6g} {S} 0 {SSA} {G} 1 1 0")
    return "\n".join(lines) + "\n"


def run(exe, algorithms):
    # multiscatter writes a file "junk" (its instrument summary) into its working directory.
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run(
            [os.path.abspath(exe), "-quiet", "-algorithms", *algorithms],
            input=profile(), capture_output=True, text=True, check=True, cwd=tmp,
        ).stdout
    rows = [list(map(float, l.split())) for l in out.splitlines() if l.strip() and not l.startswith("#")]
    a = np.array(rows)
    # columns: index, range, extinction, radius, then one apparent backscatter per FOV
    return a[:, 4:4 + len(FOVS_MRAD)]


def main():
    exe = sys.argv[1]
    total = run(exe, ["fast", "lidar"])
    single = run(exe, ["single", "none"])
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "hogan_c1.csv"), "w") as f:
        f.write(f"# multiscatter (Hogan) on C.1, radius {RADIUS*1e6:g} um, algorithms fast+lidar over single+none\n")
        f.write("depth_m," + ",".join(f"ratio_fov{v:g}mrad" for v in FOVS_MRAD) + "\n")
        for g0 in range(0, 300, 10):
            sel = (Z > 1000.0 + g0) & (Z < 1000.0 + g0 + 10.0)
            r = total[sel].mean(axis=0) / single[sel].mean(axis=0)
            f.write(f"{g0 + 5}," + ",".join(f"{x:.5f}" for x in r) + "\n")
    print(open(os.path.join(here, "hogan_c1.csv")).read())


if __name__ == "__main__":
    main()
