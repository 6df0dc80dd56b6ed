"""Runs, line by line, Mie theory and the studies."""

import datetime
import os
import sys
import warnings
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np
import xarray as xr

from . import _lidarsim
from ._data import to_xarray
from ._progress import call_with
from ._scene import Scene
from .profiles import _to_parts


class LidarsimWarning(UserWarning):
    """A note on the work asked for (a run that will take long, say)."""


def _history(what):
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    return f"{now}: {what} (lidarsim {_lidarsim.__version__}, Python {sys.version.split()[0]})"


def _scene(scene):
    if scene is None:
        return Scene.default()
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, dict):
        return Scene(scene)
    return Scene.from_toml(scene)


def run(scene=None, *, photons=None, seed=None, threads=None, progress=False):
    """Run a scene: the Monte Carlo transport (when the scene needs it) and the analytic
    single-scatter lidar equation, then the signals and retrievals the scene asks for.

    Parameters
    ----------
    scene : Scene, dict or path, optional
        The scene (a :class:`Scene`, its dict, or a TOML file); the embedded default scene
        without one.
    photons : int, optional
        Photon packets, overriding the scene's ``simulation.photons``; 0 runs the analytic
        lidar equation only. Given photons are traced whatever ``multiple_scattering`` says,
        as on the command line.
    seed : int, optional
        Random seed (overrides ``simulation.seed``). The same scene and seed give the same
        numbers at any thread count, bit for bit those of ``lidarsim run``.
    threads : int, optional
        Worker threads, 0 for all cores (overrides ``simulation.threads``).
    progress : bool or callable
        True: a tqdm bar of the Monte Carlo's batches (lines on standard error without tqdm);
        a callable: called as ``progress(done, total)``; False (default): nothing is shown.

    Returns
    -------
    xarray.Dataset
        What ``run.nc`` holds: ``energy_j`` and ``stderr_j`` [J] on (source, channel,
        fov_full_angle_mrad, range_m, order) — source ``mc`` and ``analytic``, order ``total``,
        ``1st``, ``2nd``, …, ``6th+`` (a bin a source does not compute is NaN) — with polarised light
        ``polarised_energy_j`` on a last dimension ``polarisation`` (co, cross) and
        ``depolarisation_ratio``, with a receiver the signals, with a retrieval its products
        (``mixing_ratio_*`` and others, one row per product), with ``[simulation] jacobians``
        the derivatives ``jacobian_j_m`` and ``jacobian_stderr_j_m`` [J m] of the Monte Carlo
        returns (those of ``jacobians.csv``) on (channel, fov_full_angle_mrad, range_m,
        jacobian_order, layer, jacobian_quantity) — ``jacobian_order`` ``total``, ``1st``,
        ``2nd+``; ``layer`` with ``layer_bottom_m`` and ``layer_top_m``; ``jacobian_quantity``
        ``absorption``, ``molecular_scattering``, ``particle_scattering``,
        ``particle_extinction``; NaN where a layer lacks the scatterer; units and CF names in the attributes, the
        scene's TOML text in ``attrs["scene"]``. The GIL is released while it runs; Ctrl-C
        stops it within a second (KeyboardInterrupt).
    """
    scene = _scene(scene)
    history = _history("lidarsim.run")
    parts, note = call_with(
        progress, "transport", "batches",
        lambda cb: _lidarsim.run(scene._inner, photons, seed, threads, cb, history),
    )
    if note:
        warnings.warn(note, LidarsimWarning, stacklevel=2)
    return to_xarray(parts)


class Lines:
    """A line list: a HITRAN ``.par`` file (160-character records) or lidarsim's CSV line
    format, or the built-in CO2 30012←00001 band model (:meth:`co2_band_model`)."""

    __slots__ = ("_inner",)

    def __init__(self, path, min_cm1=None, max_cm1=None):
        """The lines of ``path`` between ``min_cm1`` and ``max_cm1`` [cm⁻¹] (all without)."""
        self._inner = _lidarsim.Lines.read(os.fspath(path), min_cm1, max_cm1)

    @classmethod
    def co2_band_model(cls):
        """The built-in CO2 30012←00001 band (the lines of the default scene)."""
        lines = cls.__new__(cls)
        lines._inner = _lidarsim.Lines.co2_band_model()
        return lines

    @property
    def molecules(self):
        """The molecules of the list (``CO2``, ``H2O``, …)."""
        return list(self._inner.molecules)

    def __len__(self):
        return len(self._inner)

    def __repr__(self):
        return f"<lidarsim.Lines {self._inner.source}: {len(self)} lines of {', '.join(self.molecules)}>"


def cross_section(lines, pressure_pa, temperature_k, wavenumbers_cm1=None, *, wavelengths_nm=None,
                  molecule=None, line_shape="voigt", line_mixing=False, vmr=0.0, wing_cm1=25.0,
                  shifted_wing=False, exact=False, conventions="codata2018", self_broadening=True):
    """Absorption cross-section σ [cm² molecule⁻¹] of one molecule, line by line (as
    ``lidarsim lbl``).

    Parameters
    ----------
    lines : Lines, path or None
        The line list (a path is read with the lines that reach the grid); None: the built-in
        CO2 30012←00001 band model.
    pressure_pa : float
        Total pressure [Pa].
    temperature_k : float
        Temperature [K].
    wavenumbers_cm1 : array_like
        Vacuum wavenumbers [cm⁻¹]; an evenly spaced grid is computed on the multigrid (as
        ``lidarsim lbl``), any other point by point.
    wavelengths_nm : array_like
        Instead of ``wavenumbers_cm1``: vacuum wavelengths [nm] (ν = 10⁷/λ).
    molecule : str, optional
        Which molecule (``CO2``); needed when the lines hold several.
    line_shape : {"voigt", "sdvoigt", "ht"}
        Line profile; ``line_mixing`` adds first-order line mixing where the lines carry it.
    vmr : float
        The gas's volume mixing ratio, for self-broadening [mol/mol].
    wing_cm1 : float
        Line wing cutoff [cm⁻¹] (HAPI's default is 50 half-widths; lidarsim's a fixed 25 cm⁻¹).
    shifted_wing : bool
        Centre the cutoff window on the pressure-shifted line centre (default: unshifted, as HAPI).
    exact : bool
        Exact Faddeeva function at every line and point (slow; the reference path).
    conventions : {"codata2018", "hapi"}
        Physical constants: CODATA 2018, or HAPI 1.3's (to compare with HAPI exactly).
    self_broadening : bool
        Use γ_self for the gas's own partial pressure (``vmr``); False: air broadening only.

    Returns
    -------
    numpy.ndarray
        σ at each point given [cm² molecule⁻¹], in the order given (the array Rust computed,
        not a copy).
    """
    if (wavenumbers_cm1 is None) == (wavelengths_nm is None):
        raise ValueError("give wavenumbers_cm1 or wavelengths_nm")
    if wavelengths_nm is not None:
        lam = np.atleast_1d(np.asarray(wavelengths_nm, dtype=float))
        if not np.all(np.isfinite(lam) & (lam > 0)):
            raise ValueError("wavelengths_nm must be finite and positive")
        nu = 1e7 / lam
    else:
        nu = np.atleast_1d(np.asarray(wavenumbers_cm1, dtype=float))
    nu = np.ascontiguousarray(nu)
    if lines is None:
        lines = Lines.co2_band_model()
    elif not isinstance(lines, Lines):
        finite = nu[np.isfinite(nu)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (None, None)
        lines = Lines(lines, None if lo is None else lo - wing_cm1 - 1.0, None if hi is None else hi + wing_cm1 + 1.0)
    columns = _lidarsim.cross_section(
        lines._inner, float(pressure_pa), float(temperature_k), nu, line_shape, bool(line_mixing),
        float(vmr), float(wing_cm1), bool(shifted_wing), bool(exact), conventions,
        bool(self_broadening),
    )
    if not columns:
        raise ValueError(f"no lines of {lines._inner.source} reach {nu.min()}–{nu.max()} cm⁻¹ (with the {wing_cm1} cm⁻¹ wing)")
    if molecule is None:
        if len(columns) > 1:
            raise ValueError(f"the lines hold {', '.join(columns)}: say which with molecule=")
        return next(iter(columns.values()))
    if molecule not in columns:
        raise ValueError(f"molecule {molecule!r}: the lines hold {', '.join(columns)}")
    return columns[molecule]


def mie(m, x):
    """Mie theory of homogeneous spheres (Bohren and Huffman 1983, *Absorption and Scattering
    of Light by Small Particles*), vectorised over size parameters.

    Parameters
    ----------
    m : complex
        Refractive index relative to the medium, n + ik; a positive imaginary part absorbs
        (MIEV0 and miepython write the same as n − ik).
    x : float or array_like
        Size parameters 2πr/λ, in (0, 20000].

    Returns
    -------
    xarray.Dataset
        ``qext``, ``qsca``, ``qback`` (efficiencies, cross-section over πr²), ``g`` (asymmetry
        parameter) and ``ssa`` (single-scattering albedo) over ``size_parameter``.
    """
    xs = np.ascontiguousarray(np.atleast_1d(np.asarray(x, dtype=float)))
    out = _lidarsim.mie(complex(m), xs)
    long = {
        "qext": "extinction efficiency", "qsca": "scattering efficiency",
        "qback": "backscatter efficiency (4|S1(180°)|²/x²)", "g": "asymmetry parameter",
        "ssa": "single-scattering albedo",
    }
    return xr.Dataset(
        {k: ("size_parameter", out[k], {"units": "1", "long_name": v}) for k, v in long.items()},
        coords={"size_parameter": ("size_parameter", xs, {"units": "1", "long_name": "size parameter 2πr/λ"})},
        attrs={"refractive_index": str(complex(m))},
    )


@dataclass
class StudyResult:
    """A study's products: its tables as Datasets (None without rows) and its failures."""

    #: ``profiles.nc``: arrays on (profile, pair, retrieval), with ``class`` on profile and
    #: ``method`` on retrieval; or ``sensitivities.nc``, one row per group and on-line.
    records: Optional[xr.Dataset]
    #: ``summary.nc``: statistics on (class, pair, retrieval); None for select_lines.
    summary: Optional[xr.Dataset]
    #: The profiles that could not be studied: (id, reason).
    failed: List[Tuple[str, str]] = field(default_factory=list)


def dial(scene=None, profiles=None, *, ensemble=None, seed=None, latitude_class="all", on=(),
         photons=None, threads=0, budget=None, progress=False, strict=False):
    """A DIAL/IPDA study of a scene over an ensemble of profiles, with an error budget (as
    ``lidarsim dial``).

    Parameters
    ----------
    scene : Scene, dict or path, optional
        A scene with a ``[retrieval]``; the default scene without one.
    profiles : xarray.Dataset or path, optional
        The profiles (:mod:`lidarsim.profiles`' layout, or a profile-set file).
    ensemble : int, optional
        Instead: this many profiles per class drawn around each class's AFGL mean.
    seed : int, optional
        Seed of the ensemble and the instrument noise (default: the scene's).
    latitude_class : {"all", "tropical", "mid", "high"}
        The classes studied.
    on : sequence of str
        On-lines (the scene's line names), each paired with the retrieval's off-line; default
        the retrieval's own on-line.
    photons : int, optional
        Photons per profile; default 0 (the analytic lidar equation) without particle layers,
        the scene's with them.
    threads : int
        Worker threads, 0 for all cores.
    budget : dict, optional
        Budget steps: ``temperature_k`` (1), ``humidity_fraction`` (0.1),
        ``surface_pressure_hpa`` (1), ``frequency_offset_mhz`` (1), ``linewidth_fraction`` (0.1).
    progress : bool or callable
        As in :func:`run`, over the profiles.
    strict : bool
        As ``lidarsim dial --strict``: any failed profile (it cannot be run, is
        supersaturated, a retrieval fails) raises RuntimeError with the counts by reason and
        the first profile of each (one that cannot be run at all, before the work). False
        (default): a study where some profiles fail returns, leaves them out of the
        statistics and lists them in ``failed``.

    Returns
    -------
    StudyResult
        ``records`` (``profiles.nc``), ``summary`` (``summary.nc``) and ``failed``. A study in
        which every profile failed raises RuntimeError with the reasons, whatever ``strict``.
    """
    scene = _scene(scene)
    given = path = None
    if isinstance(profiles, xr.Dataset):
        given = _to_parts(profiles)
    elif profiles is not None:
        path = os.fspath(profiles)
    if (profiles is None) == (ensemble is None):
        raise ValueError("give profiles (a Dataset or a profile-set file) or ensemble=N")
    steps = None
    if budget is not None:
        b = {"temperature_k": 1.0, "humidity_fraction": 0.1, "surface_pressure_hpa": 1.0,
             "frequency_offset_mhz": 1.0, "linewidth_fraction": 0.1}
        unknown = set(budget) - set(b)
        if unknown:
            raise ValueError(f"budget: unknown step {sorted(unknown)} (known: {', '.join(b)})")
        b.update(budget)
        steps = tuple(float(b[k]) for k in ("temperature_k", "humidity_fraction", "surface_pressure_hpa", "frequency_offset_mhz", "linewidth_fraction"))
    history = _history("lidarsim.dial")
    records, summary, failed = call_with(
        progress, "dial", "profiles",
        lambda cb: _lidarsim.dial(scene._inner, given, path, ensemble, seed, latitude_class, list(on),
                                  photons, int(threads), steps, cb, history, bool(strict)),
    )
    return StudyResult(
        records=None if records is None else to_xarray(records),
        summary=None if summary is None else to_xarray(summary),
        failed=list(failed),
    )


def select_lines(scene=None, *, off_cm1, co2_ppm, on_cm1=(), atmospheres=(), profiles=None,
                 ensemble=None, seed=1, latitude_class="all", lines=(), max_j=40,
                 offsets_ghz=(-3, -2.5, -2, -1.5, -1, -0.5, 0, 0.5, 1, 1.5, 2, 2.5, 3),
                 layer_m=250.0, top_km=60.0, wing_cm1=25.0, temperature_uncertainty_k=1.0,
                 frequency_uncertainty_mhz=1.0, surface_pressure_uncertainty_hpa=1.0,
                 h2o_uncertainty_percent=10.0, per_profile=False, threads=0, progress=False,
                 strict=False):
    """CO2 IPDA line selection (as ``lidarsim select-lines``): for on-line positions (given,
    or scanned over the band's lines at ``offsets_ghz`` from each centre up to J″ = ``max_j``)
    against the off-line ``off_cm1`` [cm⁻¹], the weighting function, the random error of the
    scene's instrument and the systematic errors of temperature [K], frequency [MHz], surface
    pressure [hPa] and water vapour [%] knowledge, over profiles (AFGL ``atmospheres``, a
    profile-set file, or an ``ensemble`` per class) with CO2 well mixed at ``co2_ppm`` [ppm] of
    dry air at every level. Lines:
    HITRAN ``.par`` paths (default the built-in band model); the grid ``layer_m`` [m] to
    ``top_km`` [km].

    ``strict``, as ``lidarsim select-lines --strict``: any failed profile raises
    RuntimeError with the counts by reason and the first profile of each; False (default): a
    study where some profiles fail returns without them and lists them in ``failed`` (one where
    every profile failed raises either way).

    Returns
    -------
    StudyResult
        ``records``: the rows of ``sensitivities.nc``; ``failed``.
    """
    scene = _scene(scene)
    history = _history("lidarsim.select_lines")
    table, failed = call_with(
        progress, "select-lines", "profiles",
        lambda cb: _lidarsim.select_lines(
            scene._inner, float(off_cm1), float(co2_ppm), [float(v) for v in on_cm1],
            list(atmospheres), None if profiles is None else os.fspath(profiles), ensemble,
            int(seed), latitude_class, [os.fspath(p) for p in lines], int(max_j),
            [float(v) for v in offsets_ghz], float(layer_m), float(top_km), float(wing_cm1),
            (float(temperature_uncertainty_k), float(frequency_uncertainty_mhz),
             float(surface_pressure_uncertainty_hpa), float(h2o_uncertainty_percent)),
            bool(per_profile), int(threads), cb, history, bool(strict)),
    )
    return StudyResult(records=None if table is None else to_xarray(table), summary=None, failed=list(failed))
