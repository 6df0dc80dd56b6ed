"""lidarsim.plot: the figures drawn from real output files of the lidarsim binary.

The binary is $LIDARSIM_BIN, default target/release/lidarsim of this repository; without it
every test here is skipped with one line. Each test checks what was drawn (the artists, labels,
limits and legend), not pixels.
"""

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

xr = pytest.importorskip("xarray")
matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("LIDARSIM_BIN", ROOT / "target" / "release" / "lidarsim"))


import lidarsim  # noqa: E402
from lidarsim import plot as P  # noqa: E402


@pytest.fixture(scope="session")
def out(tmp_path_factory):
    """Run the binary once per scene into a temporary directory: a few seconds in all."""
    if not BIN.is_file():
        message = f"no lidarsim binary at {BIN} (set LIDARSIM_BIN or cargo build --release)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    d = tmp_path_factory.mktemp("plot")
    scenes = ROOT / "scenes"
    runs = {
        "ipda": [],  # the embedded default scene: space-borne IPDA, two FOVs
        "dial": [str(scenes / "airborne_co2_dial.toml")],  # DIAL cells and IPDA, two FOVs
        "ground": [str(scenes / "ground_rayleigh_aerosol_cloud.toml")],  # no [retrieval]
        "c1": [str(scenes / "bissonnette_c1.toml")],  # one channel, six FOVs
        "many": [str(scenes / "study_co2_ipda.toml")],  # eleven channels
    }
    for name, args in runs.items():
        subprocess.run(
            [str(BIN), "run", *args, "--out", str(d / name), "--photons", "2000",
             "--seed", "5", "--threads", "1", "--no-plots"],
            check=True, capture_output=True,
        )
    subprocess.run(
        [str(BIN), "dial", str(scenes / "study_co2_ipda.toml"), "--on",
         "R16e+0.0GHz,R16e+1.2GHz,R26e+0.0GHz", "--ensemble", "2", "--seed", "3",
         "--threads", "1", "--out", str(d / "study"), "--no-plots"],
        check=True, capture_output=True,
    )
    return d


def _run(out, name):
    return xr.open_dataset(out / name / "run.nc")


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def _series(ax):
    return [ln for ln in ax.get_lines() if hasattr(ln, "lidarsim_series")]


def _finite_limits(ax):
    for lim in (ax.get_xlim(), ax.get_ylim()):
        assert np.all(np.isfinite(lim)) and lim[1] > lim[0]


def _check_ticks(ax):
    """Tick labels a person would write: no '1000.0' (an axis whose ticks are all whole
    numbers shows them without decimals), no offset or scale text beside the axis."""
    ax.figure.canvas.draw()
    for axis, labels in ((ax.xaxis, ax.get_xticklabels()), (ax.yaxis, ax.get_yticklabels())):
        texts = [t.get_text() for t in labels if t.get_text()]
        assert not (texts and all(t.endswith(".0") for t in texts)), texts
        assert axis.get_offset_text().get_text() == ""


# --- returns ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["ipda", "dial", "ground", "c1", "many"])
def test_returns_one_axes_draws_every_channel_fov_and_source(out, name):
    ds = _run(out, name)
    fig, ax = plt.subplots()
    got = P.returns(ds, ax=ax)
    assert got is ax
    nch, nfov = ds.sizes["channel"], ds.sizes["fov_full_angle_mrad"]
    # Monte Carlo at orders total and 1, analytic at order 1.
    lines = _series(ax)
    assert len(lines) == nch * nfov * 3
    assert {ln.lidarsim_series[2] for ln in lines} == set(
        ds.fov_full_angle_mrad.values.tolist()
    )
    # One band of ± standard error per Monte Carlo line.
    assert len(ax.collections) == nch * nfov * 2
    assert ax.get_xlabel() == "range [km]"
    assert ax.get_ylabel() == "energy per gate [J]"
    assert ax.get_yscale() == "log"
    _finite_limits(ax)
    assert ax.get_xlim()[1] == pytest.approx(ds.range_m.values.max() / 1000)
    assert ax.get_legend() is not None
    # The legend sits right of the axes, not over the curves.
    fig.canvas.draw()
    leg = ax.get_legend().get_window_extent()
    assert leg.x0 >= ax.get_window_extent().x1
    _check_ticks(ax)


def test_returns_colours_apart_for_many_channels(out):
    ds = _run(out, "many")
    ax = P.returns(ds, source="analytic")
    colours = {tuple(ln.get_color()) for ln in _series(ax)}
    assert ds.sizes["channel"] == 11
    assert len(colours) == 11


def test_returns_panels_per_fov_without_ax(out):
    ds = _run(out, "ipda")
    axes = P.returns(ds)
    assert len(axes) == ds.sizes["fov_full_angle_mrad"] == 2
    for a, f in zip(axes, ds.fov_full_angle_mrad.values):
        assert {ln.lidarsim_series[2] for ln in _series(a)} == {f}
        assert a.get_xlabel() == "range [km]"
        assert f"{f:g} mrad" in a.get_title()
    assert axes[0].get_ylabel() == "energy per gate [J]"


def test_returns_selection_and_errors(out):
    ds = _run(out, "c1")
    ax = P.returns(ds, fov=[0.1, 10.0], source="mc", orders=("total",))
    assert len(_series(ax)) == 2
    assert all(ln.lidarsim_series[0] == "mc" for ln in _series(ax))
    with pytest.raises(ValueError, match="no field of view"):
        P.returns(ds, fov=3.0)
    with pytest.raises(ValueError, match="energy_j"):
        P.returns(ds.drop_vars("energy_j"))


# --- retrieval ----------------------------------------------------------------------------


def _roles(ax, role):
    return [ln for ln in ax.get_lines() if getattr(ln, "lidarsim_role", None) == role]


def test_retrieval_dial_cells_against_truth(out):
    ds = _run(out, "dial")
    ax = P.retrieval(ds)
    dial = ds.mixing_ratio_method.values == "dial"
    # Cells with a value (2000 photons leave some far Monte Carlo cells empty: named).
    valued = dial & np.isfinite(ds.mixing_ratio_retrieved.values)
    pts = _roles(ax, "retrieved") + _roles(ax, "off-scale")
    assert sum(len(ln.get_xdata()) for ln in pts) == int(valued.sum())
    if valued.sum() < dial.sum():
        assert f"{int(dial.sum() - valued.sum())} cells without a value" in ax.get_title()
    # One series per FOV and kind of returns (analytic 1, MC 1, MC total).
    assert len(_roles(ax, "retrieved")) == ds.sizes["fov_full_angle_mrad"] * 3
    truth = _roles(ax, "truth")
    assert len(truth) == 1
    t = ds.mixing_ratio_truth.values[dial]
    assert np.nanmin(truth[0].get_xdata()) == pytest.approx(t.min())
    assert ax.get_xlabel() == "CO2 dry-air mixing ratio [ppm]"
    assert ax.get_ylabel() == "altitude [km]"
    lo, hi = ax.get_xlim()
    assert lo <= t.min() and hi >= t.max()
    _finite_limits(ax)
    assert ax.get_legend() is not None
    assert ax.get_legend().get_texts()[0].get_text().startswith("truth")
    _check_ticks(ax)


def test_retrieval_wild_cell_is_clipped_and_named(out):
    ds = _run(out, "dial").load()
    v = ds.mixing_ratio_retrieved.values.copy()
    i = int(np.flatnonzero(ds.mixing_ratio_method.values == "dial")[3])
    v[i] = 1e5
    ds["mixing_ratio_retrieved"] = ds.mixing_ratio_retrieved.copy(data=v)
    ax = P.retrieval(ds)
    assert ax.get_xlim()[1] < 1000
    assert "1 cells off-scale" in ax.get_title()
    assert len(_roles(ax, "off-scale")) == 1


def test_retrieval_ipda_columns(out):
    ds = _run(out, "ipda")
    ax = P.retrieval(ds)
    n = ds.sizes["mixing_ratio_product"]
    assert sum(len(ln.get_xdata()) for ln in _roles(ax, "retrieved")) == n
    assert len(_roles(ax, "truth")) == n
    assert ax.get_ylabel() == "XCO2 [ppm]"
    # The error bars (± 0.9 ppm) are inside the axis.
    e = ds.mixing_ratio_random_error_averaged.values
    r = ds.mixing_ratio_retrieved.values
    lo, hi = ax.get_ylim()
    assert lo <= (r - e).min() and hi >= (r + e).max()
    assert "off-scale" not in ax.get_title() and "run off" not in ax.get_title()
    assert len(ax.get_xticklabels()) == ds.sizes["fov_full_angle_mrad"]
    assert ax.get_legend() is not None
    _check_ticks(ax)
    # A DIAL scene's columns on request.
    ax = P.retrieval(_run(out, "dial"), method="ipda", fov=1.0)
    assert len(_roles(ax, "truth")) == 3


def test_retrieval_without_retrieval_says_so(out):
    with pytest.raises(ValueError, match=r"no retrieval \(no \[retrieval\] in its scene"):
        P.retrieval(_run(out, "ground"))
    with pytest.raises(ValueError, match="no 'dial' rows"):
        P.retrieval(_run(out, "ipda"), method="dial")


# --- dial study ---------------------------------------------------------------------------


def test_study_errors_ipda(out):
    s = xr.open_dataset(out / "study" / "summary.nc")
    ax = P.study_errors(s)
    # summary.nc on (class, pair, retrieval): the IPDA cells that hold a value.
    ipda = np.isfinite(s.bias_ppm.where(s.method == "ipda").values)
    drawn = _roles(ax, "retrieved") + _roles(ax, "off-scale")
    # Noise-free and noisy, per class (three and all) and pair.
    assert sum(len(ln.get_xdata()) for ln in drawn) == 2 * int(ipda.sum())
    assert [t.get_text() for t in ax.get_xticklabels()] == [
        "R16e+0.0GHz", "R16e+1.2GHz", "R26e+0.0GHz"
    ]
    assert ax.get_xlabel() == "on-line (off-line off)"
    assert ax.get_ylabel() == "retrieved − true XCO2 [ppm]"
    _finite_limits(ax)
    assert ax.get_legend() is not None
    _check_ticks(ax)


def test_study_errors_dial_clips_wild_noisy_cells(out):
    s = xr.open_dataset(out / "study" / "summary.nc")
    ax = P.study_errors(s, method="dial")
    assert ax.get_ylabel() == "altitude [km]"
    assert "class all" in ax.get_title()
    _finite_limits(ax)
    noisy = s.noisy_bias_ppm.sel({"class": "all"}).where(s.method == "dial").values
    if np.nanmax(np.abs(noisy)) > 100:  # far cells of one noisy measurement
        assert "off-scale" in ax.get_title()
        assert max(abs(x) for x in ax.get_xlim()) < 100


def test_study_errors_missing_column(out):
    s = xr.open_dataset(out / "study" / "summary.nc")
    with pytest.raises(ValueError, match="noisy_sd_ppm"):
        P.study_errors(s.drop_vars("noisy_sd_ppm"))


def test_budget_table_matches_budget_csv(out):
    p = xr.open_dataset(out / "study" / "profiles.nc")
    table = P.budget_table(p)
    with open(out / "study" / "budget.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["method"] == "ipda"]
    assert rows
    for r in rows:
        key = (r["class"], r["pair"], float(r["altitude_bottom_m"]))
        got = table[key].get(r["source"], 0.0)
        assert got == pytest.approx(float(r["rms_ppm"]), rel=1e-9, abs=1e-12), r


def test_study_budget(out):
    p = xr.open_dataset(out / "study" / "profiles.nc")
    s = xr.open_dataset(out / "study" / "summary.nc")
    ax = P.study_budget(p)
    total = _roles(ax, "total")
    assert len(total) == 1
    # summary.nc on (class, pair, retrieval): the IPDA cells of class `all`, pair by pair.
    t = s.total_budget_ppm.sel({"class": "all"}).where(s.method == "ipda").values.ravel()
    want = t[np.isfinite(t)]
    np.testing.assert_allclose(total[0].get_ydata(), want, rtol=1e-9)
    assert len(_roles(ax, "budget")) >= 5
    assert ax.get_yscale() == "log"
    assert ax.get_ylabel().startswith("error [ppm]")
    assert ax.get_xlabel() == "on-line (off-line off)"
    _finite_limits(ax)
    assert ax.get_legend() is not None
    with pytest.raises(ValueError, match="profile_id"):
        P.study_budget(s)


def test_no_pyplot_show(monkeypatch, out):
    """Nothing calls plt.show() (a notebook shows figures itself; a script saves them)."""
    monkeypatch.setattr(plt, "show", lambda *a, **k: pytest.fail("plt.show() called"))
    P.returns(_run(out, "dial"))
    P.retrieval(_run(out, "dial"))


def test_module_imports_without_matplotlib():
    """plot.py imports matplotlib only inside its functions (``import lidarsim`` without it)."""
    code = (
        "import sys, importlib.util\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'matplotlib': raise ImportError('blocked')\n"
        "sys.meta_path.insert(0, Block())\n"
        f"spec = importlib.util.spec_from_file_location('p', {str(ROOT / 'python' / 'lidarsim' / 'plot.py')!r})\n"
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
        "assert 'matplotlib' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_figures_of_a_run_made_in_python():
    """The figures from lidarsim.run's Dataset (what run.nc holds), no file in between."""
    ds = lidarsim.run(photons=2000, seed=1)
    axes = np.atleast_1d(P.returns(ds))
    assert all(ax.get_xlabel() == "range [km]" for ax in axes)
    ax = P.retrieval(ds)
    assert "ppm" in ax.get_xlabel() + ax.get_ylabel()
