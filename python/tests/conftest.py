"""Shared fixtures: the repository, the `lidarsim` command line built beside this package (the
truth the package's numbers are compared with, bit for bit), and the "tests only" data of
../shared (a test that needs an absent file skips with one line naming it)."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("LIDARSIM_SHARED", ROOT.parent / "shared"))
BIN = Path(os.environ.get("LIDARSIM_BIN", ROOT / "target" / "release" / "lidarsim"))


def shared_file(relative):
    """The path of a "tests only" file of ../shared, or a skip naming it."""
    p = SHARED / relative
    if not p.is_file():
        pytest.skip(f"{p} is absent")
    return p


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
