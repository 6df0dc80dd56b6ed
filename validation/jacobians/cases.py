"""The two cases of the multiscatter Jacobian comparison (issue 40, item 2(c)), defined once.

Both make_scenes.py (lidarsim scenes and phase tables) and run_multiscatter.py (Hogan's
multiscatter) read the media from here, so the two models see the same cloud gate by gate.

Case "c1": Bissonnette et al. (1995), "LIDAR multiple scattering from clouds", Appl. Phys. B 60,
355-362, case C.1, as in scenes/bissonnette_c1.toml: ground lidar at 0 m looking up, 1064 nm,
pencil beam, top-hat fields of view 0.1-10 mrad (full angle), cloud 1000-1300 m of extinction
17.23 km^-1, single-scattering albedo 0.999908, Deirmendjian C.1 droplets (Mie table
phase_functions/bissonnette_c1_1064nm.txt: lidar ratio 19.5896 sr, g 0.837121), no air.
multiscatter describes the droplets by one radius (the width of the diffraction peak): the C.1
effective radius 6 um ((alpha+3)/b = 9/1.5 for n(r) ~ r^6 exp(-1.5 r)), as in
validation/c1_multiple_scattering/hogan_multiscatter.py, with the droplet shape of the phase
function near 180 degrees (droplet fraction 1).

Case "calipso": CALIPSO-like. The profile is multiscatter's own example
examples/hogan2008fig8.in (shipped with multiscatter 1.2.10; by its name the profile of Fig. 8 of
Hogan 2008, "Fast lidar and radar multiple-scattering models. Part I: Small-angle scattering using
the photon variance-covariance method", J. Atmos. Sci. 65, 3621-3635; the paper's text was not
available here, so that link is unchecked): 200 m gates, 532 nm, an ice cloud 4100-7100 m of
extinction 0.6 km^-1 (equivalent-area radius 50 um), a liquid cloud 1100-2100 m of 3 km^-1
(radius 10 um), lidar ratio 20 sr, single-scattering albedo 1 and g 0.85 for both, and air
extinction 1.34041e-5 exp(-z / 8 km) m^-1 (the file's values). The instrument is NOT the file's
(5 and 7.14 urad, which is not CALIPSO) but CALIOP's nominal one (Winker et al. 2009, "Overview
of the CALIPSO mission and CALIOP data processing algorithms", J. Atmos. Oceanic Technol. 26,
2310-2327): 705 km, 110 mJ at 532 nm, 1 m telescope, beam divergence 100 urad (full angle, taken
as the 1/e^2 diameter of a Gaussian beam), field of view 130 urad (full angle, top hat). Hence
"CALIPSO-like", not the paper's case. The lowest gate of the file (centred on the ground) is
left out so that every gate lies above the ground.
"""
import math

CASES = {
    "c1": dict(
        wavelength_m=1064e-9,
        lidar_altitude_m=0.0,
        looking_up=True,
        pulse_energy_j=1.0,
        telescope_diameter_m=1.0,
        optical_efficiency=1.0,
        beam_full_angle_mrad=0.0,  # pencil beam
        fov_full_angle_mrad=[0.1, 0.5, 1.0, 2.0, 5.0, 10.0],
        # gates of the lidarsim scene (altitudes of their edges, from the lidar outward)
        gate_edges_m=[1000.0 + 10.0 * k for k in range(41)],
        # particle layers, one per cloud gate: (bottom, top, extinction /m, ssa, g, radius m, S sr,
        # droplet fraction, phase-table file relative to the scene)
        layers=[
            (1000.0 + 10.0 * k, 1010.0 + 10.0 * k, 17.23e-3, 0.999908, 0.837121, 6e-6, 19.5896, 1.0,
             "../../phase_functions/bissonnette_c1_1064nm.txt")
            for k in range(30)
        ],
        air=None,
    ),
    "calipso": dict(
        wavelength_m=532e-9,
        lidar_altitude_m=705000.0,
        looking_up=False,
        pulse_energy_j=0.11,
        telescope_diameter_m=1.0,
        optical_efficiency=1.0,
        beam_full_angle_mrad=0.1,  # Gaussian, 1/e^2 diameter (lidarsim's convention)
        fov_full_angle_mrad=[0.13],
        gate_edges_m=[8100.0 - 200.0 * k for k in range(41)],
        layers=(
            [(7100.0 - 200.0 * (k + 1), 7100.0 - 200.0 * k, 0.6e-3, 1.0, 0.85, 50e-6, 20.0, 0.0,
              "hogan_ice_50um_532nm.txt") for k in range(15)]
            + [(2100.0 - 200.0 * (k + 1), 2100.0 - 200.0 * k, 3e-3, 1.0, 0.85, 10e-6, 20.0, 0.0,
                "hogan_liquid_10um_532nm.txt") for k in range(5)]
        ),
        # air extinction per 200 m gate, constant within the gate (evaluated at its centre, as
        # in the example file); Rayleigh phase without depolarisation (multiscatter's 3/(8 pi))
        air=lambda z_centre: 1.34041e-5 * math.exp(-z_centre / 8000.0),
    ),
}


def gate_centres(case):
    e = CASES[case]["gate_edges_m"]
    return [(a + b) / 2 for a, b in zip(e[:-1], e[1:])]


def layer_name(case, k):
    lo, hi = sorted(CASES[case]["layers"][k][:2])
    return f"gate {lo:.0f}-{hi:.0f} m"
