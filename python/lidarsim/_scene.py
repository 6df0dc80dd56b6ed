"""Scenes: from a TOML file or text, from a dict, edited from Python."""

import copy
import json
import math
import os
from pathlib import Path

import numpy as np

from . import _lidarsim
from ._lidarsim import SceneError


def _error(key, message):
    """A SceneError at `key` of a description given by values, as the Rust side makes them."""
    e = SceneError(f"{key}: {message}" if key else message)
    e.path, e.line, e.key = None, None, key or None
    return e


def _plain(value, path):
    """``value`` as JSON-ready Python (numpy arrays and scalars, tuples and paths made plain),
    every number finite; ``path`` (``layer[0].top_m``) names a bad value."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise _error(path, f"key {k!r} is not text")
            out[k] = _plain(v, f"{path}.{k}" if path else k)
        return out
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, float) and not math.isfinite(value):
        raise _error(path, f"`{value}` is not a finite number")
    return value


def _drop_none(value):
    """The description without its absent keys (None), as the TOML would have it."""
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_drop_none(v) for v in value]
    return value


class Scene:
    """A lidar scene: the lidar, its channels and gates, the atmosphere, particle layers, the
    surface, the instrument and the retrieval, as the TOML scene file says them (README,
    "Scene keys", for every key and its unit).

    ``Scene(dict)`` takes the same keys, values and units as the TOML file (a section is a dict,
    ``[[layer]]`` a list of dicts); numpy arrays are welcome where a list is. Relative paths
    (phase-function tables, profile files) are taken from ``base_dir`` (default: the current
    directory). Every check of the command line applies; a bad value raises
    :class:`SceneError` (a ``ValueError``) naming its key: ``layer[0].extinction_per_km: …``.

    A scene is immutable: :meth:`replace` and :meth:`with_profile` return new scenes.
    """

    __slots__ = ("_inner",)

    def __init__(self, description, base_dir=None):
        if isinstance(description, Scene):
            self._inner = description._inner
            return
        if not isinstance(description, dict):
            raise TypeError(
                "Scene(dict); for a TOML file or text use Scene.from_toml(path_or_text)"
            )
        text = json.dumps(_plain(description, ""))
        base = os.fspath(base_dir) if base_dir is not None else os.getcwd()
        self._inner = _lidarsim.Scene.from_json(text, base)

    @classmethod
    def _wrap(cls, inner):
        scene = cls.__new__(cls)
        scene._inner = inner
        return scene

    @classmethod
    def from_toml(cls, path_or_text, base_dir=None):
        """The scene of a TOML file (a path, or a string naming a file that exists) or of TOML
        text (any other string with a newline or an ``=``). A file's relative paths are taken
        from its directory, text's from ``base_dir`` (default: the current directory). Errors
        name the file, line and key."""
        is_text = (
            isinstance(path_or_text, str)
            and not os.path.isfile(path_or_text)
            and ("\n" in path_or_text or "=" in path_or_text)
        )
        if not is_text:
            return cls._wrap(_lidarsim.Scene.read(os.fspath(path_or_text)))
        base = Path(base_dir) if base_dir is not None else Path()
        return cls._wrap(_lidarsim.Scene.from_toml_text(path_or_text, os.fspath(base / "<scene text>")))

    @classmethod
    def default(cls):
        """The embedded default scene: a space-borne CO2 IPDA at 1572 nm (``lidarsim run``
        without a scene)."""
        return cls._wrap(_lidarsim.Scene.default_scene())

    def to_dict(self):
        """The scene's description as a dict (the TOML's keys; absent keys left out)."""
        return _drop_none(json.loads(self._inner.description_json()))

    def to_toml(self):
        """The scene's description as TOML text, which :meth:`from_toml` reads back."""
        return self._inner.to_toml()

    def replace(self, **sections):
        """A new scene with sections replaced: a dict merges into the section's keys (a key
        set to None is removed), anything else (a list of ``layer`` dicts, say) replaces the
        section. ``scene.replace(lidar={"fov_full_angle_mrad": [0.5, 2]})``. What the edit
        leaves unchanged (layer optics, line lists) is not computed again."""
        d = self.to_dict()
        for name, value in sections.items():
            if isinstance(value, dict) and isinstance(d.get(name), dict):
                merged = copy.deepcopy(d[name])
                for k, v in value.items():
                    if v is None:
                        merged.pop(k, None)
                    else:
                        merged[k] = v
                d[name] = merged
            elif value is None:
                d.pop(name, None)
            else:
                d[name] = value
        return Scene._wrap(self._inner.edited(json.dumps(_plain(d, ""))))

    def with_profile(self, profile):
        """A new scene with another atmospheric profile: one profile of
        :func:`lidarsim.profiles.ensemble` or :func:`lidarsim.profiles.read` (``ds.isel(profile=3)``),
        or a dict with ``altitude_m`` [m], ``pressure_pa`` [Pa], ``temperature_k`` [K] per level
        bottom up and ``gases``, a dict formula → volume mixing ratio [mol/mol] per level. The
        scene's ``co2_ppm`` still sets CO2 as its ``co2_scaling`` says (by default well mixed
        in dry air, replacing the profile's own CO2); layer optics and line lists are kept."""
        if isinstance(profile, dict):
            name = str(profile.get("name", "profile"))
            gases = list(profile.get("gases", {}).items())
        else:  # an xarray Dataset of one profile
            if "profile" in profile.dims:
                raise ValueError("with_profile takes one profile: select it with ds.isel(profile=i)")
            name = str(profile["profile"].values) if "profile" in profile.coords else "profile"
            gases = [(profile[v].attrs["gas"], profile[v]) for v in profile.data_vars if "gas" in profile[v].attrs]

        def levels(values):  # bottom up, without the NaN padding of a shorter profile
            return np.asarray(values, dtype=float)[keep].tolist()

        keep = np.isfinite(np.asarray(profile["altitude_m"], dtype=float))
        args = [levels(profile[k]) for k in ("altitude_m", "pressure_pa", "temperature_k")]
        gases = [(g, levels(v)) for g, v in gases]
        return Scene._wrap(self._inner.with_profile(name, *args, gases))

    @property
    def path(self):
        """The file the scene came from (a pseudo-path for the default scene, text or a dict)."""
        return Path(self._inner.path)

    @property
    def base_dir(self):
        """The directory relative paths are taken from."""
        return Path(self._inner.base_dir)

    @property
    def lines(self):
        """The laser lines: a dict name → vacuum wavenumber [cm⁻¹]."""
        return dict(self._inner.lines)

    @property
    def channels(self):
        """The monochromatic channels the transport follows (line-shape nodes, impurity, …):
        a dict name → vacuum wavenumber [cm⁻¹]."""
        return dict(self._inner.channels)

    @property
    def fov_full_angle_mrad(self):
        """Receiver fields of view, full angles [mrad]."""
        return list(self._inner.fov_full_angle_mrad)

    @property
    def range_m(self):
        """Range-gate centres [m]."""
        return np.asarray(self._inner.range_m)

    @property
    def simulation(self):
        """The run settings: photons, seed, batches, threads (0: all cores)."""
        photons, seed, batches, threads = self._inner.simulation
        return {"photons": photons, "seed": seed, "batches": batches, "threads": threads}

    def __repr__(self):
        lines = ", ".join(self.lines) or "no lines"
        return f"<lidarsim.Scene {self.path} ({lines}; FOV {self.fov_full_angle_mrad} mrad; {len(self.range_m)} gates)>"
