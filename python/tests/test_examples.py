"""The notebook-style examples run as a user would run them, and write their figures."""

import os
import subprocess
import sys

from conftest import ROOT


def test_cloud_xco2_bias_example_runs(tmp_path):
    out = tmp_path / "bias.png"
    env = dict(os.environ, LIDARSIM_EXAMPLE_PHOTONS="40000", MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, str(ROOT / "python" / "examples" / "cloud_xco2_bias.py"), str(out)],
                       capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 10_000
    assert "wrote" in r.stdout and "mixing_ratio_bias" in r.stdout
