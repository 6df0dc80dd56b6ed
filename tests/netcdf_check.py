#!/usr/bin/env python3
"""Check `run.nc` of `lidarsim run` against the CSV files beside it, with real NetCDF clients.

Usage: netcdf_check.py OUT_DIR SCENE_FILE [OUT_DIR SCENE_FILE ...] (`lidarsim run` outputs;
SCENE_FILE "-" for the embedded default scene, whose text is then not compared), or
netcdf_check.py --sensitivities OUT_DIR ... (`lidarsim select-lines`), or
netcdf_check.py --dial OUT_DIR ... (`lidarsim dial` or the merge of its shards).

The file is opened twice: with xarray (as users read it: CF decoding, `_FillValue` masked to
NaN, char arrays as strings) and with netCDF4-python (the netCDF-C library's own reader, for the
attributes and the raw fill values). The CSV files are read with Python's csv module. Checked:

* every row of returns.csv, backscatter.csv, signals.csv, retrieval.csv and jacobians.csv has its value in
  the file (backscatter.csv's lidar constant too, by channel), and every
  bin of the file that holds a value has its row (no extra numbers). returns.csv and
  signals.csv print 10 significant digits (`{:.9e}`), so a value of the file is compared as
  Python's `'%.9e'` prints it (both round correctly, half to even): exact equality of the text.
  retrieval.csv prints the shortest text that reads back as the same double: exact equality.
  Empty fields (and `NaN`) are missing values in the file;
* the CF attributes: Conventions, title, source, history, scene, seed, photons; units and
  long_name on every variable, bounds of range_m, ancillary_variables, _FillValue;
* `altitude_m`, each gate's altitude from the scene's own [lidar] altitude and pointing, an
  auxiliary coordinate of every variable over range_m;
* every CSV file of the directory read by pandas: its text columns load as text (README,
  "Text in CSV files"); read here with the apostrophe that marks a numeric-looking name
  removed.

`--dial`: profiles.nc and summary.nc on (profile or class, pair, retrieval) against the CSVs,
cell by cell, and their global attributes (scene, seed, lidarsim_version).

Prints one line per directory and exits 1 on the first difference.
"""

import csv
import json
import math
import sys
import time

import netCDF4
import numpy as np
import xarray as xr


def fail(msg):
    print(f"netcdf check: FAILED: {msg}")
    sys.exit(1)


def same_e9(text, value):
    """The CSV's `{:.9e}` text (empty: not computed) against the file's double."""
    if text == "":
        return math.isnan(value)
    return not math.isnan(value) and float(text) == float("%.9e" % value)


def same_exact(text, value):
    """retrieval.csv's shortest round-trip text (empty: not computed) against the double."""
    if text == "":
        return math.isnan(value)
    return not math.isnan(value) and float(text) == value


def text(field):
    """A text field of lidarsim's CSV files as the name it holds: lidarsim writes a name that
    would read as a number, a boolean or a missing value with one apostrophe in front
    (`'1064`; README, "Text in CSV files"), and one that starts with an apostrophe so too."""
    return field[1:] if field.startswith("'") else field


# Columns of lidarsim's CSV files that hold text: pandas must load each as strings (object).
CSV_TEXT_COLUMNS = {
    "source", "channel", "method", "channel_pair", "quantity", "unit", "polarisation",
    "profile_id", "id", "class", "pair", "atmosphere", "line", "reason",
}


def check_csv_text_columns(out):
    """Every CSV file of OUT: pandas (default options) reads its text columns as strings, and
    every non-empty field there, decoded, is a name (never a number's type)."""
    import glob
    import os

    import pandas as pd

    n = 0
    for path in sorted(glob.glob(os.path.join(out, "*.csv"))):
        df = pd.read_csv(path, comment="#")
        for c in df.columns:
            if c in CSV_TEXT_COLUMNS and df[c].notna().any():
                values = df[c].dropna()
                text = df[c].dtype == object or pd.api.types.is_string_dtype(df[c].dtype)
                if not text or not all(isinstance(v, str) for v in values):
                    fail(f"{path}: pandas reads the text column {c} as {df[c].dtype}")
                n += 1
    return n


def read_csv(path):
    """Header and rows, every field decoded by `text` (no number starts with an apostrophe)."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = [[text(x) for x in r] for r in csv.reader(f)]
    return rows[0], rows[1:]


def positions(ds, coord):
    """label (or exact float) -> index along a coordinate."""
    values = ds[coord].values
    return {(v if isinstance(v, str) else float(v)): i for i, v in enumerate(values)}


def check_grid_file(ds, csv_path, columns, what):
    """returns.csv or signals.csv: each row against the 5-D variables; no extra values."""
    header, rows = read_csv(csv_path)
    col = {name: header.index(name) for name in header}
    pos = {c: positions(ds, c) for c in ["source", "channel", "fov_full_angle_mrad", "range_m", "order"]}
    arrays = {c: ds[c].values for c in columns}
    for c in columns:
        if ds[c].dims != ("source", "channel", "fov_full_angle_mrad", "range_m", "order"):
            fail(f"{c} has dimensions {ds[c].dims}")
    seen = np.zeros(arrays[columns[0]].shape, dtype=bool)
    for n, row in enumerate(rows, start=2):
        # run.nc holds the totals; the co- and cross-polarised rows of a polarised run are in
        # returns.csv and depolarisation.csv only.
        if "polarisation" in col and row[col["polarisation"]] != "total":
            continue
        try:
            idx = (
                pos["source"][row[col["source"]]],
                pos["channel"][row[col["channel"]]],
                pos["fov_full_angle_mrad"][float(row[col["fov_full_angle_mrad"]])],
                pos["range_m"][float(row[col["range_m"]])],
                pos["order"][row[col["order"]]],
            )
        except KeyError as e:
            fail(f"{csv_path} line {n}: coordinate {e} is not in run.nc")
        if seen[idx]:
            fail(f"{csv_path} line {n}: a second row for one bin")
        seen[idx] = True
        for c in columns:
            v = float(arrays[c][idx])
            if not same_e9(row[col[c]], v):
                fail(f"{csv_path} line {n}, {c}: CSV {row[col[c]]}, run.nc {v!r}")
    for c in columns:
        extra = ~seen & ~np.isnan(arrays[c])
        if extra.any():
            fail(f"{c}: {int(extra.sum())} values in run.nc that {what} does not have")
    return len(rows)


def check_lidar_constant(ds, csv_path):
    """backscatter.csv's lidar_constant_j_m2 of every row is run.nc's of its channel."""
    header, rows = read_csv(csv_path)
    ch, col = header.index("channel"), header.index("lidar_constant_j_m2")
    pos = positions(ds, "channel")
    values = ds["lidar_constant_j_m2"].values
    for n, row in enumerate(rows, start=2):
        if not same_e9(row[col], float(values[pos[row[ch]]])):
            fail(f"{csv_path} line {n}: lidar constant {row[col]}, run.nc {values[pos[row[ch]]]!r}")


JACOBIAN_DIMS = ("channel", "fov_full_angle_mrad", "range_m", "jacobian_order", "layer", "jacobian_quantity")


def check_jacobians(ds, out):
    """jacobians.csv against jacobian_j_m and jacobian_stderr_j_m: every row in its bin (the
    file's channels are the lines; a row of a combination that is no line, `line:d_dnu_per_mhz`,
    is the CSV's only), the layer's edges as the CSV writes them, and every other bin
    `_FillValue`, read raw by netCDF4 (never NaN). Returns (rows checked, rows the CSV only)."""
    header, rows = read_csv(f"{out}/jacobians.csv")
    col = {name: header.index(name) for name in header}
    for c in ["jacobian_j_m", "jacobian_stderr_j_m"]:
        if ds[c].dims != JACOBIAN_DIMS:
            fail(f"{c} has dimensions {ds[c].dims}")
        if ds[c].attrs.get("units") != "J m":
            fail(f"{c} has units {ds[c].attrs.get('units')!r}")
    if ds["jacobian_j_m"].attrs.get("ancillary_variables") != "jacobian_stderr_j_m":
        fail("jacobian_j_m: ancillary_variables")
    if ds["layer_bottom_m"].attrs.get("units") != "m" or ds["layer_top_m"].attrs.get("units") != "m":
        fail("layer_bottom_m / layer_top_m: units")
    pos = {c: positions(ds, c) for c in ["channel", "fov_full_angle_mrad", "range_m", "jacobian_order", "jacobian_quantity"]}
    layers = positions(ds, "layer")
    bottom, top = ds["layer_bottom_m"].values, ds["layer_top_m"].values
    value, stderr = ds["jacobian_j_m"].values, ds["jacobian_stderr_j_m"].values
    seen = np.zeros(value.shape, dtype=bool)
    only_csv = 0
    for n, row in enumerate(rows, start=2):
        if row[col["source"]] != "mc":
            fail(f"jacobians.csv line {n}: source {row[col['source']]!r}")
        if row[col["channel"]] not in pos["channel"] and ":" in row[col["channel"]]:
            only_csv += 1
            continue
        if row[col["quantity"]] == "gas_amount":  # per relative change: the CSV's only
            only_csv += 1
            continue
        try:
            l = layers[float(row[col["layer"]])]
            idx = (
                pos["channel"][row[col["channel"]]],
                pos["fov_full_angle_mrad"][float(row[col["fov_full_angle_mrad"]])],
                pos["range_m"][float(row[col["range_m"]])],
                pos["jacobian_order"][row[col["order"]]],
                l,
                pos["jacobian_quantity"][row[col["quantity"]]],
            )
        except KeyError as e:
            fail(f"jacobians.csv line {n}: coordinate {e} is not in run.nc")
        if seen[idx]:
            fail(f"jacobians.csv line {n}: a second row for one bin")
        seen[idx] = True
        if float(row[col["layer_bottom_m"]]) != bottom[l] or float(row[col["layer_top_m"]]) != top[l]:
            fail(f"jacobians.csv line {n}: layer edges {row[col['layer_bottom_m']]}, {row[col['layer_top_m']]}")
        if row[col["derivative_j"]] or row[col["stderr_j"]]:
            fail(f"jacobians.csv line {n}: a J m derivative in the J columns")
        for c, v in [("derivative_j_m", value[idx]), ("stderr_j_m", stderr[idx])]:
            if not same_e9(row[col[c]], float(v)):
                fail(f"jacobians.csv line {n}, {c}: CSV {row[col[c]]}, run.nc {float(v)!r}")
    with netCDF4.Dataset(f"{out}/run.nc") as nc:
        for c in ["jacobian_j_m", "jacobian_stderr_j_m"]:
            v = nc.variables[c]
            v.set_auto_mask(False)
            raw = v[:]
            if np.isnan(raw).any():
                fail(f"{c} holds NaN")
            # Bins without a row: undefined (fill) or exactly 0 (the CSV leaves those out).
            other = raw[~seen]
            bad = ~((other == v.getncattr("_FillValue")) | (other == 0.0))
            if bad.any():
                fail(f"{c}: {int(bad.sum())} values that jacobians.csv does not have")
    return len(rows) - only_csv, only_csv


UNITS = {"ppm": "1e-6", "molecules_per_m2": "m-2", "molecules_per_m3": "m-3"}
SUFFIX = {"mixing_ratio": "ppm", "slant_column": "molecules_per_m2", "number_density": "molecules_per_m3"}
TEXT_COLUMNS = ["method", "source", "order", "channel_pair"]


def check_retrievals(ds, csv_path):
    """retrieval.csv against the `<quantity>_*` tables: a row's values are in the columns of its
    quantity's unit (`truth_ppm`, …), equal to `<quantity>_truth`, …; the other units' columns
    are empty."""
    header, rows = read_csv(csv_path)
    col = {name: header.index(name) for name in header}
    by_quantity = {}
    for n, row in enumerate(rows, start=2):
        by_quantity.setdefault(row[col["quantity"]], []).append((n, row))
    for q, qrows in by_quantity.items():
        dim = f"{q}_product"
        unit = SUFFIX[q]
        if ds.sizes.get(dim) != len(qrows):
            fail(f"{dim}: {ds.sizes.get(dim)} in run.nc, {len(qrows)} {q} rows in retrieval.csv")
        for c in header:
            if c == "quantity":
                continue
            other = [u for u in UNITS if u != unit and c.endswith("_" + u)]
            if other:
                for n, row in qrows:
                    if row[col[c]] != "":
                        fail(f"{csv_path} line {n}: {c} of a {q} row is {row[col[c]]!r}, not empty")
                continue
            bare = c[: -len(unit) - 1] if c.endswith("_" + unit) else c
            var = ds[f"{q}_{bare}"]
            if c in TEXT_COLUMNS or c == "shots_averaged" or c.endswith("_m") or c.endswith("_mrad"):
                pass
            elif var.attrs.get("units") != UNITS[unit]:
                fail(f"{q}_{bare}: units {var.attrs.get('units')!r} for {c}")
            for i, (n, row) in enumerate(qrows):
                v = var.values[i]
                if c in TEXT_COLUMNS:
                    if v != row[col[c]]:
                        fail(f"{csv_path} line {n}, {c}: CSV {row[col[c]]!r}, run.nc {v!r}")
                elif not same_exact(row[col[c]], float(v)):
                    fail(f"{csv_path} line {n}, {c}: CSV {row[col[c]]!r}, run.nc {float(v)!r}")
    extra = [d for d in ds.sizes if d.endswith("_product") and d[: -len("_product")] not in by_quantity]
    if extra:
        fail(f"run.nc has products {extra} that retrieval.csv does not")
    return len(rows)


def check_attributes(path, out, scene):
    summary = json.load(open(f"{out}/summary.json", encoding="utf-8"))
    with netCDF4.Dataset(path) as nc:
        if nc.data_model != "NETCDF3_64BIT_OFFSET":
            fail(f"data model {nc.data_model}")
        g = {k: nc.getncattr(k) for k in nc.ncattrs()}
        for k in ["Conventions", "title", "source", "history", "scene", "scene_file", "seed", "photons"]:
            if k not in g:
                fail(f"global attribute {k} is missing")
        if g["Conventions"] != "CF-1.8":
            fail(f"Conventions {g['Conventions']!r}")
        if not g["source"].startswith("lidarsim "):
            fail(f"source {g['source']!r}")
        if "lidarsim" not in g["history"] or not g["history"][:4].isdigit():
            fail(f"history {g['history']!r}")
        if scene is not None and g["scene"] != open(scene, encoding="utf-8").read():
            fail("the scene attribute is not the scene file's text")
        if float(g["photons"]) != summary["photons"]:
            fail(f"photons {g['photons']} vs summary.json {summary['photons']}")
        if "seed" in summary and g["seed"] != str(summary["seed"]):
            fail(f"seed {g['seed']!r} vs summary.json {summary['seed']}")
        for name, v in nc.variables.items():
            attrs = v.ncattrs()
            if name.endswith("_bounds"):
                continue
            if "long_name" not in attrs:
                fail(f"{name} has no long_name")
            if v.dtype != "S1" and "units" not in attrs:
                fail(f"{name} has no units")
        e = nc.variables["energy_j"]
        if e.ancillary_variables != "stderr_j" or "_FillValue" not in e.ncattrs():
            fail("energy_j: ancillary_variables or _FillValue missing")
        r = nc.variables["range_m"]
        b = nc.variables[r.bounds][:]
        centre = r[:]
        if b.shape != (len(centre), 2) or not np.allclose((b[:, 0] + b[:, 1]) / 2, centre, rtol=1e-15, atol=0):
            fail("range_m_bounds are not the edges of the gates")
        # The altitude of each gate's centre, from the scene's own [lidar] altitude and pointing.
        import tomllib

        lidar = tomllib.loads(g["scene"])["lidar"]
        mu = math.cos(math.radians(lidar.get("zenith_angle_deg", 0.0)))
        z = nc.variables["altitude_m"]
        if z.dimensions != ("range_m",) or z.standard_name != "altitude" or z.units != "m" or z.positive != "up":
            fail(f"altitude_m: dimensions {z.dimensions} or attributes {z.ncattrs()}")
        z0 = lidar["altitude_m"] if "altitude_m" in lidar else 1e3 * lidar.get("altitude_km", 0.0)
        if not np.allclose(z[:], z0 + mu * centre, rtol=1e-12, atol=1e-6):
            fail("altitude_m is not the lidar altitude + cos(zenith) x range")
        zb = nc.variables[z.bounds][:]
        if not np.allclose(zb, z0 + mu * b, rtol=1e-12, atol=1e-6):
            fail("altitude_m_bounds")
        for name, v in nc.variables.items():
            if "range_m" in v.dimensions and not name.startswith(("range_m", "altitude_m")):
                if "altitude_m" not in getattr(v, "coordinates", "").split():
                    fail(f"{name}: coordinates {getattr(v, 'coordinates', None)!r} lack altitude_m")


# sensitivities.csv: the Rust format of each numeric column, as Python's % operator writes it
# (exponents differ in form, `e-1` against `e-01`, not in value: compared as parsed doubles).
SENSITIVITY_FORMATS = {
    "nu_on_cm1": "%.6f", "nu_off_cm1": "%.6f", "daod_one_way": "%.6e", "wf_peak_hpa": "%.2f",
    "dxco2_per_k_ppm": "%.6e", "dxco2_per_mhz_ppm": "%.6e", "dxco2_per_hpa_ppm": "%.6e",
    "dxco2_per_10pct_h2o_ppm": "%.6e", "offset_ghz": "%.4f", "t2_on_mean": "%.6e",
    "t2_on_std": "%.6e", "random_error_ppm": "%.6e", "total_error_ppm": "%.6e",
    "rank": "%d", "profiles": "%d",
}


def check_sensitivities(out):
    """`lidarsim select-lines`: sensitivities.nc against sensitivities.csv, row by row."""
    header, rows = read_csv(f"{out}/sensitivities.csv")
    with netCDF4.Dataset(f"{out}/sensitivities.nc") as nc:
        if nc.Conventions != "CF-1.8" or not nc.source.startswith("lidarsim ") or not nc.history:
            fail("sensitivities.nc: global attributes")
        for k in ["lidarsim_version", "scene_file", "scene", "seed"]:
            if k not in nc.ncattrs():
                fail(f"sensitivities.nc: global attribute {k} is missing")
    with xr.open_dataset(f"{out}/sensitivities.nc") as ds:
        if ds.sizes["row"] != len(rows):
            fail(f"sensitivities.nc has {ds.sizes['row']} rows, the CSV {len(rows)}")
        for j, c in enumerate(header):
            var = ds[c]
            if "long_name" not in var.attrs or (c in SENSITIVITY_FORMATS and "units" not in var.attrs):
                fail(f"sensitivities.nc: {c} lacks long_name or units")
            for i, row in enumerate(rows):
                v = var.values[i]
                if c not in SENSITIVITY_FORMATS:
                    ok = v == row[j]
                elif row[j] == "":
                    ok = math.isnan(float(v))
                else:
                    ok = float(row[j]) == float(SENSITIVITY_FORMATS[c] % v)
                if not ok:
                    fail(f"sensitivities.csv line {i + 2}, {c}: CSV {row[j]!r}, sensitivities.nc {v!r}")
    print(f"netcdf check: {out}: {len(rows)} sensitivity rows equal in sensitivities.nc")


def check_dial_table(out, name, group, group_column):
    """`lidarsim dial`: NAME.nc against NAME.csv, read by netCDF4 and by xarray. The file holds
    arrays on (GROUP, pair, retrieval): GROUP the profiles (coordinate `profile`, the ids, and
    `class`) or the classes (`class`), `pair` the line pairs by name, `retrieval` each pair's
    rows in the CSV's order (`method`). Every CSV row has its cell, found from its GROUP_COLUMN,
    pair and rank among the rows of that group and pair, and every number there equals the
    CSV's (Rust's `{}`, the shortest text that reads back as the double: exact equality; an
    empty field is a missing value); every other cell is missing."""
    header, rows = read_csv(f"{out}/{name}.csv")
    col = {c: j for j, c in enumerate(header)}
    path = f"{out}/{name}.nc"
    dims = (group, "pair", "retrieval")
    with netCDF4.Dataset(path) as nc:
        if nc.data_model != "NETCDF3_64BIT_OFFSET":
            fail(f"{name}.nc: data model {nc.data_model}")
        if nc.Conventions != "CF-1.8" or not nc.source.startswith("lidarsim ") or not nc.title:
            fail(f"{name}.nc: global attributes")
        if "lidarsim" not in nc.history or not nc.history[:4].isdigit():
            fail(f"{name}.nc: history {nc.history!r}")
        summary = json.load(open(f"{out}/summary.json", encoding="utf-8"))
        g = {k: nc.getncattr(k) for k in nc.ncattrs()}
        for k in ["lidarsim_version", "scene_file", "scene", "seed", "profile_set"]:
            if k not in g:
                fail(f"{name}.nc: global attribute {k} is missing")
        if g["seed"] != str(summary["seed"]):
            fail(f"{name}.nc: seed {g['seed']!r}, summary.json {summary['seed']}")
        if not g["source"].endswith(g["lidarsim_version"]):
            fail(f"{name}.nc: lidarsim_version {g['lidarsim_version']!r}, source {g['source']!r}")
        import tomllib

        tomllib.loads(g["scene"])  # the scene's TOML text
        raw = {}
        numbers = [c for c in header if c not in (group_column, "class", "pair", "method")]
        for c in numbers:
            v = nc.variables[c]
            if v.dimensions != dims:
                fail(f"{name}.nc: {c} has dimensions {v.dimensions}, not {dims}")
            units = "1e-6" if c.endswith("_ppm") else "m" if c.endswith("_m") else "1"
            if v.getncattr("units") != units or "_FillValue" not in v.ncattrs() or "long_name" not in v.ncattrs():
                fail(f"{name}.nc: {c} units {v.getncattr('units')!r} (not {units!r}), no _FillValue or long_name")
            raw[c] = np.ma.filled(v[:].astype(np.float64), np.nan)
    with xr.open_dataset(path) as ds:
        if tuple(ds.sizes) != dims:
            fail(f"{name}.nc: dimensions {dict(ds.sizes)}, not {dims}")
        for c in ("class", "method", "altitude_bottom_m", "altitude_top_m"):
            if c not in ds.coords:
                fail(f"{name}.nc: {c} is not a coordinate")
        groups = [str(x) for x in ds[group].values]
        pairs = [str(x) for x in ds["pair"].values]
        methods = [str(x) for x in ds["method"].values]
        classes = [str(x) for x in ds["class"].values]
        decoded = {c: ds[c].values for c in numbers}
    seen = np.zeros(raw[numbers[0]].shape, dtype=bool)
    rank = {}
    for i, row in enumerate(rows):
        key = (row[col[group_column]], row[col["pair"]])
        k = rank.get(key, 0)
        rank[key] = k + 1
        try:
            at = (groups.index(key[0]), pairs.index(key[1]), k)
        except ValueError:
            fail(f"{name}.csv line {i + 2}: {key} is not in {name}.nc")
        if methods[k] != row[col["method"]]:
            fail(f"{name}.csv line {i + 2}: method {row[col['method']]!r}, {name}.nc {methods[k]!r}")
        if group == "profile" and classes[at[0]] != row[col["class"]]:
            fail(f"{name}.csv line {i + 2}: class {row[col['class']]!r}, {name}.nc {classes[at[0]]!r}")
        seen[at] = True
        for reader, values in [("netCDF4", raw), ("xarray", decoded)]:
            for c in numbers:
                v = float(values[c][at])
                t = row[col[c]]
                ok = math.isnan(v) if t == "" else (not math.isnan(v) and float(t) == v)
                if not ok:
                    fail(f"{name}.csv line {i + 2}, {c}: CSV {t!r}, {name}.nc by {reader} {v!r}")
    for c in numbers:
        if (~seen & ~np.isnan(raw[c])).any():
            fail(f"{name}.nc: {c} has values no row of {name}.csv has")
    return len(rows)


def check_dial(out):
    """`lidarsim dial`: profiles.nc and summary.nc against profiles.csv and summary.csv."""
    n_profiles = check_dial_table(out, "profiles", "profile", "profile_id")
    n_summary = check_dial_table(out, "summary", "class", "class")
    print(
        f"netcdf check: {out}: {n_profiles} profile rows equal in profiles.nc, "
        f"{n_summary} summary rows equal in summary.nc"
    )


def main(args):
    if args and args[0] == "--sensitivities":
        for out in args[1:]:
            check_sensitivities(out)
            check_csv_text_columns(out)
        return
    if args and args[0] == "--dial":
        for out in args[1:]:
            check_dial(out)
            check_csv_text_columns(out)
        return
    if len(args) % 2:
        fail("arguments: OUT_DIR SCENE pairs")
    for out, scene in zip(args[::2], args[1::2]):
        t0 = time.time()
        path = f"{out}/run.nc"
        check_attributes(path, out, None if scene == "-" else scene)
        n_text = check_csv_text_columns(out)
        with xr.open_dataset(path) as ds:
            if "altitude_m" not in ds["energy_j"].coords:
                fail("xarray does not see altitude_m as a coordinate of energy_j")
            n_ret = check_grid_file(ds, f"{out}/returns.csv", ["energy_j", "stderr_j"], "returns.csv")
            check_grid_file(
                ds,
                f"{out}/backscatter.csv",
                [
                    "attenuated_backscatter_per_m_sr",
                    "attenuated_backscatter_stderr_per_m_sr",
                    "range_corrected_signal_j_m2",
                    "range_corrected_signal_stderr_j_m2",
                ],
                "backscatter.csv",
            )
            check_lidar_constant(ds, f"{out}/backscatter.csv")
            n_sig = n_prod = 0
            try:
                open(f"{out}/signals.csv").close()
                has_signals = True
            except FileNotFoundError:
                has_signals = False
            if has_signals:
                n_sig = check_grid_file(
                    ds,
                    f"{out}/signals.csv",
                    ["signal_photoelectrons", "background_photoelectrons", "dark_electrons", "noise_std_photoelectrons", "snr"],
                    "signals.csv",
                )
            elif "snr" in ds:
                fail("run.nc has signals but there is no signals.csv")
            try:
                n_prod = check_retrievals(ds, f"{out}/retrieval.csv")
            except FileNotFoundError:
                if any(d.endswith("_product") for d in ds.sizes):
                    fail("run.nc has retrievals but there is no retrieval.csv")
            n_jac = 0
            try:
                open(f"{out}/jacobians.csv").close()
                has_jacobians = True
            except FileNotFoundError:
                has_jacobians = False
            if has_jacobians:
                n_jac, only_csv = check_jacobians(ds, out)
                print(
                    f"netcdf check: {out}: {n_jac} jacobians.csv rows equal in jacobian_j_m "
                    f"({only_csv} rows of combinations that are no line)"
                )
            elif any(d in ds.sizes for d in ["jacobian_order", "layer", "jacobian_quantity"]):
                fail("run.nc has Jacobians but there is no jacobians.csv")
        print(
            f"netcdf check: {out}: {n_ret} returns, {n_sig} signal and {n_prod} retrieval rows "
            f"equal in run.nc (xarray {xr.__version__}, netCDF4 {netCDF4.__version__}, "
            f"{time.time() - t0:.2f} s); {n_text} text columns read as text by pandas"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
