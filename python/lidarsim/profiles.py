"""Atmospheric profiles as ``xarray.Dataset`` objects on (profile, level).

A profile set (a file of ``lidarsim profiles generate`` or ``profiles convert``, or an
ensemble drawn here) becomes a Dataset with the coordinates ``profile`` (the id),
``latitude_deg``, ``longitude_deg``, ``time_utc``, ``latitude_class``, and per level
``altitude_m`` [m], ``pressure_pa`` [Pa], ``temperature_k`` [K] and one volume mixing ratio
[mol/mol] per gas (the variable named as the gas, ``CO2``; its ``gas`` attribute says so).
Levels run bottom up; a profile with fewer levels than the longest is padded with NaN.
:func:`lidarsim.dial` takes such a Dataset as its profiles, and :meth:`lidarsim.Scene.with_profile`
one profile of it.
"""

import numpy as np
import xarray as xr

from . import _lidarsim

__all__ = ["ensemble", "read"]

# CF standard names (table version 93) of the gases that have one.
_STANDARD_NAMES = {
    "CO2": "mole_fraction_of_carbon_dioxide_in_air",
    "CH4": "mole_fraction_of_methane_in_air",
    "O3": "mole_fraction_of_ozone_in_air",
    "N2O": "mole_fraction_of_nitrous_oxide_in_air",
    "CO": "mole_fraction_of_carbon_monoxide_in_air",
}


def _to_dataset(d):
    n, levels = len(d["id"]), d["levels"]

    def grid(a):
        return a.reshape(n, levels)  # a view of the Rust buffer

    data = {
        "altitude_m": (("profile", "level"), grid(d["altitude_m"]), {"units": "m", "long_name": "geometric altitude of the level", "standard_name": "altitude"}),
        "pressure_pa": (("profile", "level"), grid(d["pressure_pa"]), {"units": "Pa", "long_name": "air pressure", "standard_name": "air_pressure"}),
        "temperature_k": (("profile", "level"), grid(d["temperature_k"]), {"units": "K", "long_name": "air temperature", "standard_name": "air_temperature"}),
    }
    for gas, vmr in d["vmr"].items():
        attrs = {"units": "mol mol-1", "long_name": f"volume mixing ratio of {gas} (moist air)", "gas": gas}
        if gas in _STANDARD_NAMES:
            attrs["standard_name"] = _STANDARD_NAMES[gas]
        data[gas] = (("profile", "level"), grid(vmr), attrs)
    weight = d["weight"]
    coords = {
        "profile": ("profile", np.array(d["id"], dtype=object), {"long_name": "profile id"}),
        "latitude_deg": ("profile", d["latitude_deg"], {"units": "degrees_north", "standard_name": "latitude"}),
        "longitude_deg": ("profile", d["longitude_deg"], {"units": "degrees_east", "standard_name": "longitude"}),
        "time_utc": ("profile", np.array(d["time_utc"], dtype=object), {"long_name": "time (ISO 8601, UTC; empty when unknown)"}),
        "latitude_class": ("profile", np.array(d["class"], dtype=object), {"long_name": "latitude class: tropical (|latitude| < 30°), mid (30–50°), high (> 50°)"}),
    }
    if np.isfinite(weight).any():
        coords["weight"] = ("profile", weight, {"long_name": "profile weight (NaN: none)"})
    return xr.Dataset(data, coords=coords, attrs={"title": d["name"], "comment": "\n".join(d["notes"])})


def _to_parts(ds):
    """A Dataset of this module's layout as the dict the Rust side reads."""
    if "profile" not in ds.dims:
        ds = ds.expand_dims("profile")
    n = ds.sizes["profile"]
    levels = ds.sizes["level"]

    def flat(name):
        return np.ascontiguousarray(ds[name].transpose("profile", "level").values, dtype=float).reshape(-1)

    ids = [str(x) for x in ds["profile"].values] if "profile" in ds.coords else [str(i) for i in range(n)]

    def meta(name, default):
        return np.ascontiguousarray(ds[name].values, dtype=float) if name in ds.coords else np.full(n, default)

    return {
        "name": ds.attrs.get("title", "profiles given"),
        "notes": [x for x in ds.attrs.get("comment", "").split("\n") if x],
        "id": ids,
        "latitude_deg": meta("latitude_deg", 45.0),
        "longitude_deg": meta("longitude_deg", 0.0),
        "time_utc": [str(x) for x in ds["time_utc"].values] if "time_utc" in ds.coords else [""] * n,
        "weight": meta("weight", np.nan),
        "levels": levels,
        "altitude_m": flat("altitude_m"),
        "pressure_pa": flat("pressure_pa"),
        "temperature_k": flat("temperature_k"),
        "vmr": {ds[v].attrs["gas"]: flat(v) for v in ds.data_vars if "gas" in ds[v].attrs},
    }


def read(path):
    """The profile set in ``path`` (lidarsim's profile-set format) as a Dataset."""
    return _to_dataset(_lidarsim.read_profiles(str(path)))


def ensemble(n, seed, latitude_class=None, atmosphere=None, co2_ppm=None, error_model=None,
             co2_std_ppm=None, ps_std_hpa=None, max_rh_percent=100.0, rh_over="water",
             co2_scaling="well_mixed"):
    """``n`` profiles drawn around a mean profile with the representative NWP forecast-error
    covariance (as ``lidarsim profiles generate``).

    Parameters
    ----------
    n : int
        Number of profiles.
    seed : int
        Seed of the random generator (same seed, same profiles).
    latitude_class : {"tropical", "mid", "high"}, optional
        The mean is the class's AFGL mean (tropical; mid-latitude summer + winter; sub-arctic
        summer + winter).
    atmosphere : str, optional
        The mean is this AFGL atmosphere (``us_standard``, ``tropical``, …).
    co2_ppm : float, optional
        CO2 of the mean [ppm], applied as ``co2_scaling`` says.
    error_model : path, optional
        A per-level error table (p_hPa, T_std_K, lnq_std[, CO2_std_ppmv]) instead of the
        embedded representative NWP forecast error.
    co2_std_ppm : float, optional
        CO2 standard deviation at every level [ppm] (default 0: not perturbed).
    ps_std_hpa : float, optional
        Surface-pressure standard deviation [hPa] (default 0.7).
    max_rh_percent : float
        Cap water vapour at this relative humidity [%].
    rh_over : {"water", "ice"}
        Relative humidity over water, or over ice below 273.16 K.
    co2_scaling : {"well_mixed", "profile_shape"}
        ``well_mixed``: ``co2_ppm`` is the dry-air mole fraction at every level (the mean's CO2
        replaced or added); ``profile_shape``: the mean's own CO2 rescaled by one factor to
        that dry-air column average.

    Returns
    -------
    xarray.Dataset
        The profiles on (profile, level); its ``comment`` says how they were made.
    """
    return _to_dataset(_lidarsim.ensemble(
        int(n), int(seed), latitude_class, atmosphere, co2_ppm,
        None if error_model is None else str(error_model), co2_std_ppm, ps_std_hpa,
        float(max_rh_percent), rh_over, co2_scaling,
    ))
