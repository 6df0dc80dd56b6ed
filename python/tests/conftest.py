"""Shared fixtures: the repository, the `lidarsim` command line built beside this package (the
truth the package's numbers are compared with, bit for bit), and the "tests only" data of
../shared (a test that needs an absent file skips with one line naming it)."""

import math
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("LIDARSIM_SHARED", ROOT.parent / "shared"))
BIN = Path(os.environ.get("LIDARSIM_BIN", ROOT / "target" / "release" / "lidarsim"))

# No test writes into the user's Mie cache (README, "The Mie cache"): set before any test runs,
# so every `lidarsim` the tests start (the `cli` fixture, the README's examples) inherits it and
# the package in this process reads it when it resolves a scene with a Mie layer.
os.environ["LIDARSIM_CACHE_DIR"] = "off"


def shared_file(relative):
    """The path of a "tests only" file of ../shared, or a skip naming it."""
    p = SHARED / relative
    if not p.is_file():
        pytest.skip(f"{p} is absent")
    return p


def text(field):
    """A text field of lidarsim's CSV files as the name it holds: a name that would read as a
    number (`1064`) is written with one apostrophe in front (README, "Text in CSV files")."""
    return field[1:] if field.startswith("'") else field


def as_written(v, digits):
    """A number as lidarsim's CSV files write it with Rust's `{:.Ne}` (`1.500000000e-3`,
    `0.000000000e0`; an empty field for no value)."""
    if not math.isfinite(v):
        return ""
    mantissa, exponent = f"{v:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def same_but_history(a, b):
    """Two Datasets identical in every variable, coordinate and attribute but `history` (when
    and by what each was made)."""
    import xarray as xr

    a, b = a.copy(), b.copy()
    a.attrs.pop("history")
    b.attrs.pop("history")
    xr.testing.assert_identical(a, b)


@pytest.fixture(scope="session")
def cli():
    """Run the command line: cli("run", "--out", d, …) → CompletedProcess (checked)."""
    if not BIN.is_file():
        message = f"no lidarsim binary at {BIN} (cargo build --release, or set LIDARSIM_BIN)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)

    def run(*args):
        return subprocess.run([str(BIN), *map(str, args)], check=True, capture_output=True, text=True)

    return run


@pytest.fixture
def root():
    return ROOT
