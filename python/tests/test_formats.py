"""The CSV files as pandas loads them, whole path (command line → files → pandas with its
defaults): one type per column in every run, one unit per numeric column."""

import pandas as pd
import pytest
from conftest import ROOT, shared_file

# The files of `lidarsim run` with a scattering-order column.
ORDER_FILES = ["returns", "backscatter", "signals", "retrieval", "weighting", "jacobians"]
# A numeric column's unit, by the suffix of its name.
UNIT_SUFFIXES = ("_ppm", "_molecules_per_m2", "_molecules_per_m3", "_j_m", "_j", "_m", "_mrad")


@pytest.fixture(scope="module")
def runs(cli, tmp_path_factory):
    """The airborne DIAL scene with Jacobians, analytic only (`--photons 0`: order 1 only) and
    with the Monte Carlo (every order)."""
    d = tmp_path_factory.mktemp("formats")
    scene = ROOT / "validation" / "figures" / "airborne_co2_jacobians.toml"
    out = {}
    for photons in ["0", "3000"]:
        out[photons] = d / photons
        cli("run", scene, "--photons", photons, "--seed", "3", "--no-plots", "--no-netcdf",
            "--out", out[photons])
    return out


def test_order_loads_as_text_in_every_run(runs):
    """`order` is text in every file of every run: a run with `--photons 0` has only single
    scattering, which must not load as an integer column where the others load as text."""
    seen = {}
    for photons, d in runs.items():
        for name in ORDER_FILES:
            path = d / f"{name}.csv"
            if not path.exists():
                continue
            order = pd.read_csv(path)["order"]
            assert pd.api.types.is_string_dtype(order), (photons, name, order.dtype)
            seen.setdefault(name, set()).update(order.unique())
    assert seen["returns"] >= {"1st", "2nd", "2nd+", "total"}, seen
    analytic = pd.read_csv(runs["0"] / "returns.csv")
    assert set(analytic["order"]) == {"1st"} and set(analytic["source"]) == {"analytic"}
    # Every file but the Monte Carlo's own (weighting, jacobians) exists in both runs.
    assert {n for n in ORDER_FILES if (runs["0"] / f"{n}.csv").exists()} == {
        "returns", "backscatter", "signals", "retrieval"}


def test_weighting_csv_has_one_unit_per_column_and_sums_to_the_products(runs):
    """weighting.csv: each row's numbers are in the columns of its product's unit, the other
    units' columns empty; and by Euler's relation (an IPDA retrieval is homogeneous of degree
    one in the gas, docs/retrieval.md) its derivatives sum over the layers to the product of
    retrieval.csv, column for column of the same unit."""
    w = pd.read_csv(runs["3000"] / "weighting.csv")
    r = pd.read_csv(runs["3000"] / "retrieval.csv")
    assert "unit" not in w.columns and "derivative" not in w.columns
    for c in w.columns:
        if pd.api.types.is_numeric_dtype(w[c]) and c != "layer":
            assert c.endswith(UNIT_SUFFIXES), c
    unit = {"mixing_ratio": "ppm", "slant_column": "molecules_per_m2", "number_density": "molecules_per_m3"}
    for q, u in unit.items():
        rows = w[w.quantity == q]
        assert len(rows) > 0, q
        for v in ["derivative", "stderr_independent"]:
            assert rows[f"{v}_{u}"].notna().all(), (q, v)
            for other in set(unit.values()) - {u}:
                assert rows[f"{v}_{other}"].isna().all(), (q, v, other)
    checked = 0
    for method, q in [("ipda", "mixing_ratio"), ("ipda_virtual_sigma", "slant_column")]:
        u = unit[q]
        sums = w[w.method == method].groupby(["order", "fov_full_angle_mrad"])[f"derivative_{u}"].sum()
        products = r[(r.method == method) & (r.source == "mc")].set_index(
            ["order", "fov_full_angle_mrad"])[f"retrieved_{u}"]
        for key, s in sums.items():
            assert s == pytest.approx(products[key], rel=1e-5), (method, key)
            checked += 1
    assert checked == 8


def test_jacobians_csv_has_one_unit_per_column(runs):
    """jacobians.csv: ∂E/∂θ of a coefficient θ [1/m] in J m (`_j_m`), the derivative per
    relative change of the gases (`gas_amount`) in J (`_j`), each row in its unit's columns
    only. `gas_amount` = k_gas ∂E/∂k_abs with k_gas ≥ 0: where a layer's absorption
    derivative is well known, its gas-amount derivative has the same sign."""
    j = pd.read_csv(runs["3000"] / "jacobians.csv")
    assert "unit" not in j.columns and "derivative" not in j.columns
    gas = j.quantity == "gas_amount"
    assert gas.any() and (~gas).any()
    for v in ["derivative", "stderr"]:
        assert j.loc[gas, f"{v}_j"].notna().all() and j.loc[gas, f"{v}_j_m"].isna().all()
        assert j.loc[~gas, f"{v}_j_m"].notna().all() and j.loc[~gas, f"{v}_j"].isna().all()
    key = ["channel", "fov_full_angle_mrad", "range_m", "order", "layer"]
    a = j[j.quantity == "absorption"].set_index(key)
    g = j[gas].set_index(key)
    both = a.merge(g, left_index=True, right_index=True, suffixes=("_a", "_g"))
    sure = both[both["derivative_j_m_a"].abs() > 5 * both["stderr_j_m_a"]]
    assert len(sure) > 10
    assert ((sure["derivative_j_m_a"] > 0) == (sure["derivative_j_g"] > 0)).all()


def test_a_converted_sets_numeric_ids_load_as_text_and_read_back(cli, tmp_path):
    """ECMWF 52's profile ids are numbers (`1`, `2`, …): `profiles convert` writes them marked
    as text (`'1`), so pandas loads `profile` as strings; lidarsim reads them back as the ids
    (`profiles.read`, `--profile-id 7`)."""
    import lidarsim

    levels = shared_file("data/profiles/ecmwf52_chevallier_101L.csv")
    meta = shared_file("data/profiles/ecmwf52_chevallier_meta.csv")
    out = tmp_path / "e52.csv"
    cli("profiles", "convert", "--format", "ecmwf52", "--levels", levels, "--meta", meta,
        "--co2-ppm", "420", "--out", out, "--quiet")
    table = pd.read_csv(out, comment="#")
    assert pd.api.types.is_string_dtype(table["profile"]), table["profile"].dtype
    ids = list(dict.fromkeys(table["profile"]))
    assert len(ids) == 49 and all(i.startswith("'") and i[1:].isdigit() for i in ids), ids[:5]
    back = lidarsim.profiles.read(out)
    assert list(back["profile"].values) == [i[1:] for i in ids]
    gen = tmp_path / "gen.csv"
    cli("profiles", "generate", "--mean-profile", out, "--profile-id", ids[6][1:], "--n", "2",
        "--seed", "1", "--out", gen, "--quiet")
    assert len(set(pd.read_csv(gen, comment="#")["profile"])) == 2
