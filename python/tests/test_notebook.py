"""A notebook's habits: Ctrl-C stops a run within a second, the GIL is free while it runs,
progress is shown when asked and nothing is printed otherwise."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest

import lidarsim
from conftest import ROOT

# Each child installs Python's own SIGINT handler: a process started in the background by a
# shell (a CI job, `nohup … &`) inherits SIGINT ignored, and Python then leaves it ignored; a
# terminal or a notebook kernel delivers Ctrl-C to this handler.
LONG_RUN = textwrap.dedent(
    """
    import signal, sys, time, lidarsim
    signal.signal(signal.SIGINT, signal.default_int_handler)
    scene = lidarsim.Scene.default()
    print("started", flush=True)
    t = time.monotonic()
    try:
        lidarsim.run(scene, photons=400_000_000, threads=2)
    except KeyboardInterrupt:
        print(f"interrupted {time.monotonic():.6f}", flush=True)
        sys.exit(3)
    print("finished", flush=True)
    """
)


def test_ctrl_c_stops_a_run_within_a_second():
    """SIGINT to a Python process in the middle of a long run (minutes of photons): it
    raises KeyboardInterrupt within a second of the signal."""
    # Two seconds in, the transport runs: the default scene's optics take well under that.
    late = interrupt(LONG_RUN, after_s=2.0)
    assert late < 1.0, f"stopped {late:.2f} s after the signal"


LONG_STUDY = textwrap.dedent(
    """
    import signal, sys, time, lidarsim
    signal.signal(signal.SIGINT, signal.default_int_handler)
    scene = lidarsim.Scene.from_toml(sys.argv[1])
    print("started", flush=True)
    try:
        lidarsim.dial(scene, ensemble=2000, seed=1, threads=2)
    except KeyboardInterrupt:
        print(f"interrupted {time.monotonic():.6f}", flush=True)
        sys.exit(3)
    print("finished", flush=True)
    """
)


def interrupt(code, *args, after_s=2.0):
    """Seconds from SIGINT to KeyboardInterrupt in a Python process running `code`."""
    p = subprocess.Popen([sys.executable, "-c", code, *map(str, args)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "started"
        time.sleep(after_s)
        assert p.poll() is None, p.stderr.read()
        sent = time.monotonic()
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 3, (out, err)
    return float(out.split()[-1]) - sent


def test_ctrl_c_stops_a_study_at_its_next_profile():
    """A study stops before its next profile (the one under way finishes: here a few tens of
    milliseconds; a study whose profiles run a Monte Carlo each waits for that one)."""
    late = interrupt(LONG_STUDY, ROOT / "scenes" / "study_co2_ipda.toml", after_s=3.0)
    assert late < 1.0, f"stopped {late:.2f} s after the signal"


def test_the_gil_is_released_during_a_run():
    """A Python thread keeps running while lidarsim.run works on another."""
    counts = []
    done = threading.Event()

    def count():
        n = 0
        while not done.is_set():
            n += 1
            if n % 1000 == 0:
                counts.append(time.monotonic())
        return n

    t = threading.Thread(target=count)
    t.start()
    start = time.monotonic()
    lidarsim.run(photons=100_000, seed=1, threads=1)
    end = time.monotonic()
    done.set()
    t.join()
    during = [c for c in counts if start < c < end]
    assert end - start > 0.2
    # With the GIL held the counter would stop for the whole run; it ticks all along.
    assert len(during) > 100
    gaps = [b - a for a, b in zip(during, during[1:])]
    assert max(gaps) < 0.25 * (end - start)


def test_progress_callback_sees_every_batch_and_nothing_is_printed(capfd):
    seen = []
    lidarsim.run(photons=40_000, seed=1, progress=lambda done, total: seen.append((done, total)))
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert seen and seen[-1][0] == seen[-1][1] > 0
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    lidarsim.run(photons=40_000, seed=1)
    assert capfd.readouterr() == ("", "")


def test_progress_true_draws_a_tqdm_bar(capfd):
    pytest.importorskip("tqdm")
    lidarsim.run(photons=40_000, seed=1, progress=True)
    out, err = capfd.readouterr()
    assert "transport" in err and "100%" in err


def test_progress_is_shown_from_a_subprocess_without_a_terminal():
    """From `subprocess` (no TTY) a bar still reaches standard error."""
    code = "import lidarsim; lidarsim.run(photons=40_000, seed=1, progress=True)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout == ""
    assert "transport" in r.stderr


def test_a_bad_progress_is_refused():
    with pytest.raises(TypeError, match="progress"):
        lidarsim.run(photons=0, progress="yes")
