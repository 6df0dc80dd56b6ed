"""Profiles and studies against the command line: the same files' contents, and a study that
fails everywhere fails."""

import numpy as np
import pytest
import xarray as xr

import lidarsim
from conftest import ROOT, same_but_history


def same_table(ds, path):
    """A study Dataset is its NetCDF file (but for `history`)."""
    with xr.open_dataset(path) as f:
        same_but_history(ds, f.load())


def test_ensemble_is_profiles_generate(cli, tmp_path):
    """profiles.ensemble draws what `lidarsim profiles generate` writes (its file keeps nine
    significant digits, altitudes in m, pressures in hPa, gases in ppmv)."""
    out = tmp_path / "e.csv"
    cli("profiles", "generate", "--n", 4, "--seed", 7, "--class", "mid", "--co2-ppm", 415, "--out", out)
    ens = lidarsim.profiles.ensemble(4, seed=7, latitude_class="mid", co2_ppm=415)
    file = lidarsim.profiles.read(out)
    assert ens.sizes == file.sizes and list(ens.data_vars) == list(file.data_vars)
    for v in ("altitude_m", "pressure_pa", "temperature_k", "CO2", "H2O"):
        np.testing.assert_allclose(ens[v], file[v], rtol=1e-8, equal_nan=True)
    assert ens["CO2"].attrs["standard_name"] == "mole_fraction_of_carbon_dioxide_in_air"
    assert ens["pressure_pa"].attrs["units"] == "Pa"
    assert set(ens["latitude_class"].values) == {"mid"}


def test_dial_is_the_command_line(cli, tmp_path):
    """A study of the default scene over a generated ensemble: profiles.nc and summary.nc."""
    cli("dial", "--ensemble", 2, "--seed", 4, "--class", "mid", "--out", tmp_path, "--no-plots")
    r = lidarsim.dial(ensemble=2, seed=4, latitude_class="mid", threads=1)
    same_table(r.records, tmp_path / "profiles.nc")
    same_table(r.summary, tmp_path / "summary.nc")
    assert r.failed == []


def test_dial_over_a_dataset_is_the_study_of_its_file(cli, tmp_path):
    """Profiles read into a Dataset and handed back give the study of the file."""
    set_file = tmp_path / "set.csv"
    cli("profiles", "generate", "--n", 2, "--seed", 5, "--class", "tropical", "--out", set_file)
    cli("dial", "--profiles", set_file, "--seed", 2, "--out", tmp_path / "d", "--no-plots")
    r = lidarsim.dial(profiles=lidarsim.profiles.read(set_file), seed=2)
    same_table(r.records, tmp_path / "d" / "profiles.nc")
    by_path = lidarsim.dial(profiles=set_file, seed=2)
    same_but_history(by_path.records, r.records)


def test_a_study_where_every_profile_fails_raises():
    """Every profile without CO2 (the scene retrieves CO2): a RuntimeError that says why, not
    an empty success."""
    ens = lidarsim.profiles.ensemble(3, seed=1, latitude_class="mid").drop_vars("CO2")
    with pytest.raises(RuntimeError, match="CO2"):
        lidarsim.dial(profiles=ens, seed=1)


def test_select_lines_is_the_command_line(cli, tmp_path):
    args = ["--off-cm1", 6360.61, "--co2-ppm", 420, "--on-cm1", "6358.655,6359.967", "--atmosphere", "us_standard,tropical"]
    cli("select-lines", *args, "--out", tmp_path, "--no-plots", "--threads", 1)
    r = lidarsim.select_lines(off_cm1=6360.61, co2_ppm=420, on_cm1=[6358.655, 6359.967],
                              atmospheres=["us_standard", "tropical"])
    same_table(r.records, tmp_path / "sensitivities.nc")
    assert r.summary is None and r.failed == []


def test_study_arguments_are_checked():
    with pytest.raises(ValueError, match="profiles"):
        lidarsim.dial()
    with pytest.raises(ValueError, match="latitude class"):
        lidarsim.dial(ensemble=2, latitude_class="polar-ish")
    with pytest.raises(ValueError, match="budget"):
        lidarsim.dial(ensemble=2, budget={"pressure": 1})
    with pytest.raises(ValueError, match="no .retrieval."):
        lidarsim.dial(ROOT / "scenes" / "bissonnette_c1.toml", ensemble=2)
    # The ranges of the command line's options hold for the arguments too, named by argument.
    with pytest.raises(ValueError, match="budget step humidity_fraction"):
        lidarsim.dial(ensemble=2, budget={"humidity_fraction": 50.0})
    with pytest.raises(ValueError, match="layer_m: "):
        lidarsim.select_lines(off_cm1=6360.61, co2_ppm=420, layer_m=-250.0)
    with pytest.raises(ValueError, match="co2_ppm: "):
        lidarsim.select_lines(off_cm1=6360.61, co2_ppm=float("nan"))
    with pytest.raises(ValueError, match="co2_std_ppm: "):
        lidarsim.profiles.ensemble(3, seed=1, co2_std_ppm=-1.0)
    with pytest.raises(ValueError, match="rh_over"):
        lidarsim.profiles.ensemble(3, seed=1, rh_over="steam")


@pytest.fixture
def set_with_a_short_profile(cli, tmp_path):
    """Three tropical profiles, the first cut at 700 hPa (about 3 km): it does not reach the
    top of the default scene's retrieval nor a 4 km layer of line selection."""
    import pandas as pd

    full = tmp_path / "full.csv"
    cli("profiles", "generate", "--n", 3, "--seed", 5, "--class", "tropical", "--co2-ppm", 420,
        "--out", full)
    t = pd.read_csv(full, comment="#", dtype={"profile": str, "time_utc": str})
    first = t["profile"] == t["profile"].iloc[0]
    t = t[~first | (t["pressure_hPa"] >= 700.0)]
    out = tmp_path / "set.csv"
    t.to_csv(out, index=False)
    return out, t["profile"].iloc[0]


def test_strict_makes_a_failed_profile_an_error(set_with_a_short_profile):
    """`strict=True` is `--strict`: one failed profile of three raises RuntimeError naming the
    policy; without it the study returns the other two and lists the failed one."""
    path, short = set_with_a_short_profile
    r = lidarsim.dial(profiles=path, seed=2)
    assert [f[0] for f in r.failed] == [short]
    assert r.records.sizes["profile"] == 2
    with pytest.raises(RuntimeError, match="strict: any failed profile is an error"):
        lidarsim.dial(profiles=path, seed=2, strict=True)

    args = dict(off_cm1=6360.61, co2_ppm=410, on_cm1=[6360.04], profiles=path, layer_m=4000.0,
                top_km=40.0, per_profile=True)
    r = lidarsim.select_lines(**args)
    assert [f[0] for f in r.failed] == [short]
    with pytest.raises(RuntimeError, match="strict: any failed profile is an error"):
        lidarsim.select_lines(**args, strict=True)
