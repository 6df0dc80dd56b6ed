"""Progress of long work: a tqdm bar when asked for and tqdm is installed, else a callback."""

import sys


class _Bar:
    """A tqdm bar driven by (done, total) reports, made at the first report (when the total
    is known)."""

    def __init__(self, desc, unit):
        from tqdm.auto import tqdm

        self._tqdm, self._desc, self._unit, self._bar = tqdm, desc, unit, None

    def __call__(self, done, total):
        if self._bar is None:
            self._bar = self._tqdm(desc=self._desc, unit=self._unit, total=total or None)
        elif total and self._bar.total != total:
            self._bar.total = total
            self._bar.refresh()
        self._bar.update(done - self._bar.n)

    def close(self):
        if self._bar is not None:
            self._bar.close()


class _Lines:
    """Without tqdm: a line on standard error at every tenth of the work."""

    def __init__(self, desc, unit):
        self._desc, self._unit, self._tenth = desc, unit, -1

    def __call__(self, done, total):
        if total:
            tenth = 10 * done // total
            if tenth > self._tenth:
                self._tenth = tenth
                print(f"{self._desc}: {done}/{total} {self._unit}", file=sys.stderr)

    def close(self):
        pass


class _Call:
    def __init__(self, fn):
        self._fn = fn

    def __call__(self, done, total):
        self._fn(done, total)

    def close(self):
        pass


def reporter(progress, desc, unit):
    """What ``progress`` asks for: False or None, nothing (None is returned); True, a tqdm bar
    (lines on standard error without tqdm); a callable, called as ``progress(done, total)``.
    The result has ``close()``."""
    if progress is None or progress is False:
        return None
    if progress is True:
        try:
            return _Bar(desc, unit)
        except ImportError:
            return _Lines(desc, unit)
    if callable(progress):
        return _Call(progress)
    raise TypeError(f"progress must be True, False or a callable (done, total), not {progress!r}")


def call_with(progress, desc, unit, fn):
    """``fn(callback)`` with the callback ``progress`` asks for, closed afterwards."""
    bar = reporter(progress, desc, unit)
    try:
        return fn(bar)
    finally:
        if bar is not None:
            bar.close()
