"""Every Python code block of README.md runs as written, on a shipped scene: the package's
example, and the xarray and pandas snippets that read the files of `lidarsim run` (written
first by the command line into `out/`, where the README's `lidarsim run` puts them)."""

import os
import re
import subprocess
import sys

import pytest

from conftest import ROOT

lidarsim = pytest.importorskip("lidarsim", reason="the lidarsim package is not built (scripts/test-python)")


def python_blocks(path):
    """The ```python blocks of a Markdown file: (first line number, code)."""
    text = path.read_text(encoding="utf-8")
    blocks = []
    for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M):
        blocks.append((text.count("\n", 0, m.start()) + 2, m.group(1)))
    return blocks


BLOCKS = python_blocks(ROOT / "README.md")


def test_the_readme_has_python_examples():
    # The package's example, and at least one snippet each for xarray and pandas.
    assert len(BLOCKS) >= 3, BLOCKS
    assert any("xr.open_dataset" in code for _, code in BLOCKS)
    assert any("pd.read_csv" in code for _, code in BLOCKS)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, cli):
    """A directory whose `out/` holds the files `lidarsim run` writes for the default scene."""
    d = tmp_path_factory.mktemp("readme")
    cli("run", "--photons", "20000", "--seed", "1", "--no-plots", "--out", d / "out")
    return d


@pytest.mark.parametrize("line,code", BLOCKS, ids=[f"README.md:{n}" for n, _ in BLOCKS])
def test_readme_python_block_runs(line, code, workdir):
    env = dict(os.environ, MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, "-c", code], cwd=workdir, capture_output=True, text=True,
                       env=env, timeout=600)
    assert r.returncode == 0, f"README.md:{line}: the example fails:\n{code}\n{r.stderr}"
