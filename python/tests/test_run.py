"""lidarsim.run against the command line (bit for bit), closed forms of the single-scatter
lidar equation, and the Monte Carlo's order 1 against the analytic equation."""

import csv
import math

import numpy as np
import pytest
import xarray as xr

import lidarsim
from conftest import ROOT, as_written, same_but_history, shared_file, text


@pytest.mark.parametrize(
    "scene, photons",
    [(None, 20_000), ("airborne_co2_dial.toml", 4_000), ("ground_rayleigh_aerosol_cloud.toml", 20_000)],
)
def test_run_is_the_command_line_bit_for_bit(cli, tmp_path, scene, photons):
    """The Dataset is run.nc as xarray opens it (every variable, coordinate and attribute but
    `history`), at another thread count; and energy_j is returns.csv's column as written."""
    path = None if scene is None else ROOT / "scenes" / scene
    args = ["run"] + ([] if path is None else [path])
    cli(*args, "--out", tmp_path, "--photons", photons, "--seed", 5, "--threads", 2, "--no-plots")
    ds = lidarsim.run(path, photons=photons, seed=5, threads=1)
    with xr.open_dataset(tmp_path / "run.nc") as f:
        same_but_history(ds, f.load())
    rows = 0
    with open(tmp_path / "returns.csv") as f:
        for r in csv.DictReader(f):
            if r["polarisation"] != "total":
                continue
            at = dict(source=r["source"], channel=text(r["channel"]), order=r["order"],
                      fov_full_angle_mrad=float(r["fov_full_angle_mrad"]), range_m=float(r["range_m"]))
            # returns.csv writes 10 significant digits ({:.9e}); run.nc (above) every bit.
            assert as_written(ds["energy_j"].sel(at).item(), 9) == r["energy_j"]
            assert as_written(ds["stderr_j"].sel(at).item(), 9) == r["stderr_j"]
            rows += 1
    assert rows > 100


def platt_scene(top_m, g):
    """The scene of the Rust suite's Platt test (tests/clouds.rs), as a dict."""
    return {
        "lidar": {"altitude_m": 0.0, "zenith_angle_deg": 0.0, "pulse_energy_j": 1.0,
                  "beam_divergence_full_angle_mrad": 0.0, "telescope_diameter_m": 1.0,
                  "optical_efficiency": 1.0, "fov_full_angle_mrad": 1.0},
        "channel": [{"name": "1064", "wavelength_nm": 1064.0}],
        "gates": {"start_m": 990.0, "end_m": 1600.0, "width_m": 2.0},
        "layer": [{"name": "cloud", "base_m": 1000.0, "top_m": top_m, "extinction_per_km": 17.23,
                   "single_scattering_albedo": 1.0, "phase": {"kind": "henyey_greenstein", "g": g}}],
    }


@pytest.mark.parametrize("top_m, g", [(1058.04, 0.85), (1580.38, 0.5)])
def test_analytic_single_scattering_is_platt_closed_form(top_m, g):
    """Σ E r²/A over the cloud = (1 − e^(−2τ))/(2S), S the lidar ratio (Platt 1979, "Lidar
    and radiometric observations of cirrus clouds", J. Appl. Meteorol. 18, 1130)."""
    ds = lidarsim.run(lidarsim.Scene(platt_scene(top_m, g)), photons=0)
    e = ds["energy_j"].sel(source="analytic", order="1st").isel(channel=0, fov_full_angle_mrad=0)
    area = math.pi * 0.25
    gamma = float((e * ds["range_m"] ** 2 / area).sum())
    tau = 17.23e-3 * (top_m - 1000.0)
    s = 4 * math.pi * (1 + g) ** 3 / (1 - g * g)  # HG at 180°, normalised to 4π
    assert gamma == pytest.approx((1 - math.exp(-2 * tau)) / (2 * s), rel=1e-4)


def test_analytic_returns_are_the_lidar_equation_quadrature():
    """E = E₀ η A ∫ β e^(−2σ(r − base))/r² dr per gate, β = ϖσP(180°)/(4π), by a fine
    midpoint rule (numpy), against the analytic returns to 1e-8 in every gate of the layer."""
    d = platt_scene(1100.0, 0.7)
    d["lidar"].update(pulse_energy_j=0.1, optical_efficiency=0.7, telescope_diameter_m=0.4)
    d["layer"][0].update(single_scattering_albedo=0.9, extinction_per_km=5.0)
    d["gates"] = {"start_m": 1000.0, "end_m": 1100.0, "width_m": 5.0}
    ds = lidarsim.run(lidarsim.Scene(d), photons=0)
    e = ds["energy_j"].sel(source="analytic", order="1st").isel(channel=0, fov_full_angle_mrad=0).values
    sigma, g = 5e-3, 0.7
    beta = 0.9 * sigma * ((1 - g * g) / (1 + g) ** 3) / (4 * math.pi)
    k = 0.1 * 0.7 * math.pi * 0.2 ** 2
    for i, (lo, hi) in enumerate(ds["range_m_bounds"].values):
        n = 20_000
        r = lo + (np.arange(n) + 0.5) * (hi - lo) / n
        truth = k * np.sum(beta * np.exp(-2 * sigma * (r - 1000.0)) / r**2) * (hi - lo) / n
        assert e[i] == pytest.approx(truth, rel=1e-8)


def test_c1_order_one_is_the_lidar_equation_and_platt():
    """C.1 (Bissonnette et al. 1995): the Monte Carlo's order 1 agrees with the analytic
    equation within 4 standard errors + 1 % wherever its error is below 10 % (the Rust suite's
    rule), and the analytic integral over the cloud is Platt's with miepython's lidar ratio."""
    ds = lidarsim.run(ROOT / "scenes" / "bissonnette_c1.toml", photons=200_000, seed=3)
    mc = ds["energy_j"].sel(source="mc", order="1st")
    se = ds["stderr_j"].sel(source="mc", order="1st")
    an = ds["energy_j"].sel(source="analytic", order="1st")
    judged = (mc > 0) & (se <= 0.10 * mc)
    assert int(judged.sum()) > 50
    assert bool((abs(mc - an) <= 4 * se + 0.01 * an).where(judged, True).all())
    summary = shared_file("reference/c1_summary.csv")
    with open(summary) as f:
        rows = list(csv.DictReader(l for l in f if not l.startswith("#")))
    ref = next(r for r in rows if r["lambda_nm"] == "1064")
    s, ssa = float(ref["lidar_ratio_sr"]), float(ref["ssa"])
    # Gates 1000–1300 m cover the cloud; the smallest FOV holds the whole single scattering.
    e = an.isel(channel=0, fov_full_angle_mrad=0).sel(range_m=slice(1000, 1300))
    gamma = float((e * e["range_m"] ** 2 / (math.pi * 0.25)).sum())
    tau = 17.23e-3 * 300.0
    # Platt's S is σ_ext/β; the scene's albedo enters β (the file's S is for ϖ = its own).
    assert gamma == pytest.approx((1 - math.exp(-2 * tau)) / (2 * s) * 0.999908 / ssa, rel=2e-3)


def test_same_numbers_at_any_thread_count():
    a = lidarsim.run(photons=10_000, seed=9, threads=1)
    b = lidarsim.run(photons=10_000, seed=9, threads=2)
    same_but_history(a, b)


def test_received_energy_never_exceeds_the_emitted():
    ds = lidarsim.run(ROOT / "scenes" / "bissonnette_c1.toml", photons=20_000, seed=1)
    total = ds["energy_j"].sel(order="total").sum(("range_m",))
    assert float(total.max()) < 1.0  # pulse_energy_j = 1


def test_result_arrays_are_the_buffers_rust_filled():
    """No copy of the results: every numeric variable of the Dataset but the dimension
    coordinates (which pandas indexes) is the numpy array that owns the Rust vector."""
    from lidarsim import _lidarsim
    from lidarsim._data import to_xarray

    parts, _ = _lidarsim.run(lidarsim.Scene.default()._inner, 2000, 1, 1, None, "")
    ds = to_xarray(parts)
    for name, dims, values, _ in parts[1]:
        if isinstance(values, np.ndarray) and list(dims) != [name]:
            assert np.shares_memory(ds[name].values, values), name


POLARISED_CLOUD = """
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.5
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 4.0]
polarisation = "linear"
[[channel]]
name = "355"
wavelength_nm = 355.0
[gates]
start_m = 1400.0
end_m = 2400.0
width_m = 50.0
[[layer]]
name = "cloud"
base_m = 1500.0
top_m = 1700.0
extinction_per_km = 5.0
single_scattering_albedo = 1.0
phase = { kind = "henyey_greenstein", g = 0.8 }
[simulation]
photons = 20000
max_order = 3
multiple_scattering = "always"
"""


def test_polarised_returns_are_the_csv_rows(cli, tmp_path):
    """With polarised light the Dataset (and run.nc) carry co and cross on a last dimension
    `polarisation`, and the depolarisation ratio: returns.csv's co/cross rows and
    depolarisation.csv's δ as written; co + cross is the total to rounding."""
    scene_file = tmp_path / "pol.toml"
    scene_file.write_text(POLARISED_CLOUD)
    cli("run", scene_file, "--out", tmp_path / "out", "--seed", 2, "--no-plots")
    ds = lidarsim.run(lidarsim.Scene.from_toml(scene_file), seed=2)
    with xr.open_dataset(tmp_path / "out" / "run.nc") as f:
        same_but_history(ds, f.load())
    assert ds["polarised_energy_j"].dims[-1] == "polarisation"
    assert list(ds["polarisation"].values) == ["co", "cross"]
    parts = ds["polarised_energy_j"].sum("polarisation", skipna=False)
    total = ds["energy_j"]
    ok = np.isfinite(parts)
    np.testing.assert_allclose(parts.where(ok), total.where(ok), rtol=1e-12, atol=0)
    checked = 0
    with open(tmp_path / "out" / "returns.csv") as f:
        for r in csv.DictReader(f):
            if r["polarisation"] == "total":
                continue
            at = dict(source=r["source"], channel=text(r["channel"]), order=r["order"], polarisation=r["polarisation"],
                      fov_full_angle_mrad=float(r["fov_full_angle_mrad"]), range_m=float(r["range_m"]))
            assert as_written(ds["polarised_energy_j"].sel(at).item(), 9) == r["energy_j"]
            assert as_written(ds["polarised_stderr_j"].sel(at).item(), 9) == r["stderr_j"]
            checked += 1
    with open(tmp_path / "out" / "depolarisation.csv") as f:
        for r in csv.DictReader(f):
            at = dict(source=r["source"], channel=text(r["channel"]), order=r["order"],
                      fov_full_angle_mrad=float(r["fov_full_angle_mrad"]), range_m=float(r["range_m"]))
            assert as_written(ds["depolarisation_ratio"].sel(at).item(), 9) == r["delta"]
            assert as_written(ds["depolarisation_ratio_stderr"].sel(at).item(), 9) == r["delta_stderr"]
            checked += 1
    assert checked > 200
    # Single scattering by spheres keeps the polarisation: the analytic δ is 0 in the cloud.
    assert float(ds["depolarisation_ratio"].sel(source="analytic", order="1st").max()) == 0.0


JACOBIAN_SCENE = """
description = "Jacobians: a cloud in a coarse molecular atmosphere, a cloud above its top"

[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.5
optical_efficiency = 0.5
fov_full_angle_mrad = [0.5, 2.0]

[[channel]]
name = "532"
wavelength_nm = 532.0

[[channel]]
name = "1064"
wavelength_nm = 1064.0

[gates]
start_m = 900.0
end_m = 1500.0
width_m = 50.0

[atmosphere]
standard = "us_standard"
layer_thickness_m = 500.0
top_m = 1300.0

[[layer]]
name = "cloud"
base_m = 1000.0
top_m = 1200.0
extinction_per_km = 5.0
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.8 }

[[layer]]
name = "cloud above the molecules"
base_m = 1300.0
top_m = 1450.0
extinction_per_km = 2.0
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.7 }

[simulation]
photons = 4000
max_order = 4
jacobians = true
"""


def test_jacobians_are_the_command_line_and_jacobians_csv(cli, tmp_path):
    """With `jacobians = true` the Dataset is run.nc as xarray opens it (bit for bit, at
    another thread count), and jacobian_j_m / jacobian_stderr_j_m hold jacobians.csv's rows
    as written, on (channel, fov, gate, jacobian_order, layer, jacobian_quantity); every bin
    no row names is NaN (a layer without the scatterer), and there are such bins."""
    scene_file = tmp_path / "jac.toml"
    scene_file.write_text(JACOBIAN_SCENE)
    cli("run", scene_file, "--out", tmp_path / "out", "--seed", 4, "--threads", 2, "--no-plots")
    ds = lidarsim.run(lidarsim.Scene.from_toml(scene_file), seed=4, threads=1)
    with xr.open_dataset(tmp_path / "out" / "run.nc") as f:
        same_but_history(ds, f.load())
    j, se = ds["jacobian_j_m"], ds["jacobian_stderr_j_m"]
    assert j.dims == ("channel", "fov_full_angle_mrad", "range_m", "jacobian_order", "layer", "jacobian_quantity")
    assert j.attrs["units"] == "J m" and se.attrs["units"] == "J m"
    assert list(ds["jacobian_order"].values) == ["total", "1st", "2nd+"]
    assert list(ds["jacobian_quantity"].values) == [
        "absorption", "molecular_scattering", "particle_scattering", "particle_extinction"]
    seen = np.zeros(j.shape, dtype=bool)
    with open(tmp_path / "out" / "jacobians.csv") as f:
        for r in csv.DictReader(f):
            if r["quantity"] == "gas_amount":  # per relative change: the CSV's only
                continue
            at = dict(channel=text(r["channel"]), fov_full_angle_mrad=float(r["fov_full_angle_mrad"]),
                      range_m=float(r["range_m"]), jacobian_order=r["order"], layer=float(r["layer"]),
                      jacobian_quantity=r["quantity"])
            # ∂E/∂θ per coefficient θ [1/m]: the J m columns; the J columns are gas_amount's.
            assert as_written(j.sel(at).item(), 9) == r["derivative_j_m"]
            assert as_written(se.sel(at).item(), 9) == r["stderr_j_m"]
            assert r["derivative_j"] == r["stderr_j"] == ""
            layer = ds["layer"].sel(layer=float(r["layer"]))
            assert float(r["layer_bottom_m"]) == layer["layer_bottom_m"].item()
            assert float(r["layer_top_m"]) == layer["layer_top_m"].item()
            index = tuple(int(np.flatnonzero(ds[d].values == v)[0]) for d, v in at.items())
            seen[index] = True
    assert seen.sum() > 1000
    # Bins without a row: undefined (NaN) or exactly 0 (the CSV leaves those out).
    rest = j.values[~seen]
    assert (np.isnan(rest) | (rest == 0)).all()
    assert np.array_equal(np.isnan(rest), np.isnan(se.values[~seen]))
    assert (~seen).any()
    # The molecular-scattering derivative is undefined exactly above the molecules' top.
    mol = j.sel(jacobian_quantity="molecular_scattering").isel(channel=0, fov_full_angle_mrad=0, range_m=0,
                                                              jacobian_order=0)
    above = ds["layer_bottom_m"] >= 1300.0
    assert np.isnan(mol.where(above, drop=True)).all() and np.isfinite(mol.where(~above, drop=True)).all()
