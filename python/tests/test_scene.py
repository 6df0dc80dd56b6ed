"""Scenes from TOML and from values: the same scene either way, every check of the Rust side
with a message that names the key, edits from Python."""

import shutil

import numpy as np
import pytest
import xarray as xr

import lidarsim
from conftest import ROOT

C1 = ROOT / "scenes" / "bissonnette_c1.toml"


def analytic(scene):
    return lidarsim.run(scene, photons=0)["energy_j"].sel(source="analytic", order="1st")


def test_a_dict_is_the_same_scene_as_its_toml():
    """to_dict → Scene(dict) (relative paths from the file's directory) gives the returns of
    the file, to the bit; to_toml → from_toml too."""
    file = lidarsim.Scene.from_toml(C1)
    d = file.to_dict()
    assert d["layer"][0]["extinction_per_km"] == 17.23
    from_dict = lidarsim.Scene(d, base_dir=C1.parent)
    from_text = lidarsim.Scene.from_toml(file.to_toml(), base_dir=C1.parent)
    a = analytic(file)
    xr.testing.assert_identical(a, analytic(from_dict))
    xr.testing.assert_identical(a, analytic(from_text))


def test_numpy_values_are_taken():
    d = lidarsim.Scene.from_toml(C1).to_dict()
    d["lidar"]["fov_full_angle_mrad"] = np.array([0.5, 2.0])
    d["gates"]["width_m"] = np.float64(20.0)
    s = lidarsim.Scene(d, base_dir=C1.parent)
    assert s.fov_full_angle_mrad == [0.5, 2.0]
    assert len(s.range_m) == 20


def message_of(fn):
    with pytest.raises(lidarsim.SceneError) as e:
        fn()
    assert isinstance(e.value, ValueError)
    return str(e.value)


def test_a_bad_value_names_its_key_with_the_message_of_the_file():
    """The check is the Rust side's: the same words after the key, whether the scene came
    from a dict (named by its key path) or from TOML (named by file, line and key)."""
    d = lidarsim.Scene.from_toml(C1).to_dict()
    d["layer"][0]["extinction_per_km"] = -1.0
    from_dict = message_of(lambda: lidarsim.Scene(d, base_dir=C1.parent))
    assert from_dict.startswith("layer[0].extinction_per_km: ")
    text = C1.read_text().replace("extinction_per_km = 17.23", "extinction_per_km = -1.0")
    from_toml = message_of(lambda: lidarsim.Scene.from_toml(text, base_dir=C1.parent))
    assert ":" in from_toml and "extinction_per_km" in from_toml
    assert from_toml.endswith(from_dict.split(": ", 1)[1])
    e = pytest.raises(lidarsim.SceneError, lidarsim.Scene, d, base_dir=C1.parent).value
    assert e.key == "layer[0].extinction_per_km" and e.line is None and e.path is None


@pytest.mark.parametrize(
    "edit, starts",
    [
        (lambda d: d["lidar"].update(fov=1.0), "lidar.fov: unknown field `fov`"),
        (lambda d: d["gates"].update(width_m="wide"), "gates.width_m: invalid type: string"),
        (lambda d: d["lidar"].update(fov_full_angle_mrad=[0.5, float("nan")]),
         "lidar.fov_full_angle_mrad[1]: `nan` is not a finite number"),
        (lambda d: d["layer"][0].update(top_m=900.0), "layer[0]"),
        (lambda d: d.pop("gates"), "missing field `gates`"),
    ],
)
def test_every_kind_of_bad_value_names_its_key(edit, starts):
    d = lidarsim.Scene.from_toml(C1).to_dict()
    edit(d)
    assert message_of(lambda: lidarsim.Scene(d, base_dir=C1.parent)).startswith(starts)
    e = pytest.raises(lidarsim.SceneError, lidarsim.Scene, d, base_dir=C1.parent).value
    assert e.line is None and e.path is None
    assert e.key is None or str(e).startswith(e.key + ": ")


def test_relative_paths_are_taken_from_base_dir(tmp_path):
    """A copied scene file fails on its phase-function path (named at its key); its dict with
    the original directory as base_dir works."""
    copy = tmp_path / "c1.toml"
    shutil.copy(C1, copy)
    m = message_of(lambda: lidarsim.Scene.from_toml(copy))
    assert str(copy) in m and "phase" in m
    d = lidarsim.Scene.from_toml(C1).to_dict()
    assert lidarsim.Scene(d, base_dir=C1.parent).base_dir == C1.parent


def test_replace_edits_a_section_and_keeps_the_rest():
    s = lidarsim.Scene.from_toml(C1)
    t = s.replace(lidar={"fov_full_angle_mrad": [0.5, 2]}, simulation={"photons": 1000})
    assert t.fov_full_angle_mrad == [0.5, 2.0]
    assert s.fov_full_angle_mrad == [0.1, 0.5, 1.0, 2.0, 5.0, 10.0]
    assert t.simulation["photons"] == 1000
    # The same scene written out with those values, to the bit.
    d = s.to_dict()
    d["lidar"]["fov_full_angle_mrad"] = [0.5, 2.0]
    d["simulation"]["photons"] = 1000
    xr.testing.assert_identical(analytic(t), analytic(lidarsim.Scene(d, base_dir=C1.parent)))
    # A layer list replaces the layers; a bad edit is named at its key.
    thin = dict(s.to_dict()["layer"][0], extinction_per_km=1.0)
    deep = dict(range_m=1255.0, fov_full_angle_mrad=0.1, channel="1064")
    # The gate 250–260 m into the cloud: about e^(−2·0.255·(1 − 17.23))/17.23 ≈ 228 times
    # more from the thin one (less the curvature of the exponential over the gate).
    ratio = float(analytic(s.replace(layer=[thin])).sel(deep)) / float(analytic(s).sel(deep))
    assert ratio == pytest.approx(np.exp(-2 * 0.255 * (1 - 17.23)) / 17.23, rel=0.02)
    assert message_of(lambda: s.replace(lidar={"telescope_diameter_m": -1})).startswith("lidar.telescope_diameter_m: ")


def test_with_profile_takes_one_profile_of_an_ensemble():
    """A profile of profiles.ensemble swapped into the default scene is the profile given by
    values in the description (its levels), and changes the gas absorption."""
    ens = lidarsim.profiles.ensemble(3, seed=2, latitude_class="mid")
    scene = lidarsim.Scene.default()
    p = ens.isel(profile=1)
    swapped = scene.with_profile(p)
    given = swapped.to_dict()["atmosphere"]["profile"]
    keep = np.isfinite(p["altitude_m"].values)
    np.testing.assert_array_equal(given["altitude_m"], p["altitude_m"].values[keep])
    np.testing.assert_array_equal(given["temperature_k"], p["temperature_k"].values[keep])
    by_dict = scene.with_profile({
        "name": str(p["profile"].values),
        "altitude_m": p["altitude_m"].values, "pressure_pa": p["pressure_pa"].values,
        "temperature_k": p["temperature_k"].values,
        "gases": {p[v].attrs["gas"]: p[v].values for v in ens.data_vars if "gas" in ens[v].attrs},
    })
    xr.testing.assert_identical(analytic(swapped), analytic(by_dict))
    assert not analytic(swapped).equals(analytic(scene))
    with pytest.raises(ValueError, match="one profile"):
        scene.with_profile(ens)
