"""lidarsim from Python: a simulation testbed for atmospheric lidars (DIAL and IPDA above all).

Scenes from TOML or from values, runs and studies as ``xarray.Dataset`` objects with units in
their attributes, line-by-line cross-sections and Mie theory as numpy arrays. The work is done
by the lidarsim Rust library, in this process, with the GIL released; the numbers are bit for
bit those of the ``lidarsim`` command line for the same scene and seed.

>>> import lidarsim
>>> scene = lidarsim.Scene.default()                  # space-borne CO2 IPDA at 1572 nm
>>> ds = lidarsim.run(scene, photons=20_000, seed=1)   # energy_j on (source, channel, fov, range, order)
>>> ds["energy_j"].sel(source="analytic", order="1st")

See the README's Python section.
"""

from . import plot, profiles
from ._api import Lines, LidarsimWarning, StudyResult, cross_section, dial, mie, run, select_lines
from ._lidarsim import SceneError, __version__
from ._scene import Scene

__all__ = [
    "Lines",
    "LidarsimWarning",
    "Scene",
    "SceneError",
    "StudyResult",
    "__version__",
    "cross_section",
    "dial",
    "mie",
    "plot",
    "profiles",
    "run",
    "select_lines",
]
