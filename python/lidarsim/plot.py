"""Figures of lidarsim's results with matplotlib: the figures the command line draws.

Every function takes an :class:`xarray.Dataset` laid out as lidarsim's NetCDF files
(``lidarsim.run()`` returns what ``run.nc`` holds; ``xr.open_dataset`` reads the files the
command line writes), draws into a matplotlib ``Axes`` given as ``ax`` (or a new figure) and
returns what it drew into. Nothing calls ``plt.show()``.

=====================  ==========================  ==========================================
function               data                        figure (the CLI's file)
=====================  ==========================  ==========================================
:func:`returns`        ``run.nc``                  received energy against range
                                                   (``returns.png``)
:func:`retrieval`      ``run.nc`` with a           DIAL cells against the truth
                       ``[retrieval]``             (``dial.png``), or the IPDA columns
:func:`study_errors`   ``summary.nc`` of ``dial``  bias and random error per class and pair
:func:`study_budget`   ``profiles.nc`` of ``dial`` error budget per line pair
                                                   (``budget.png``)
=====================  ==========================  ==========================================

matplotlib is imported inside the functions, so ``import lidarsim`` works without it. The
depolarisation ratio has no function here: ``run.nc`` does not hold the polarised returns yet
(``depolarisation.csv`` does).
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["returns", "retrieval", "study_errors", "study_budget"]

# Font sizes fit for a slide (points).
_LABEL = 12
_TICK = 11
_TITLE = 12
_LEGEND = 10

# Colours of the kinds of returns a retrieval used, as the CLI draws them (analytic blue,
# Monte Carlo red); Monte Carlo single scattering in between.
_KIND_COLOUR = {
    ("analytic", "1"): "tab:blue",
    ("mc", "total"): "tab:red",
    ("mc", "1"): "tab:orange",
}
_KIND_LABEL = {
    ("analytic", "1"): "analytic, single scattering",
    ("mc", "total"): "Monte Carlo, all orders",
    ("mc", "1"): "Monte Carlo, single scattering",
}
# Latitude classes as the CLI colours them.
_CLASS_COLOUR = {
    "tropical": "#c83c1e",
    "mid": "#1e783c",
    "high": "#1e46be",
    "all": "black",
}
_FOV_MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]
_FOV_STYLES = ["-", "--", ":", "-."]
# Units of a mole fraction as lidarsim writes them, and their names on an axis.
_FRACTION_UNITS = {"1e-6": "ppm", "1e-9": "ppb", "1e-12": "ppt", "1": "mol/mol"}
_GASES = ("CO2", "CH4", "H2O", "N2O", "CO", "O3", "NO2", "SO2", "NH3", "HDO", "O2")


# --- helpers ------------------------------------------------------------------------------


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "lidarsim.plot needs matplotlib: pip install matplotlib "
            "(or pip install 'lidarsim[plot]')"
        ) from e
    return plt


def _new_axes(figsize):
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=figsize, layout="constrained")
    return ax


def _require(ds, names, what):
    missing = [n for n in names if n not in ds.variables]
    if missing:
        raise ValueError(
            f"{what}: the dataset has no {', '.join(repr(m) for m in missing)} "
            f"(has: {', '.join(sorted(map(str, ds.variables)))})"
        )


def _text(values):
    """Text coordinates as Python strings (NetCDF char arrays may come back as bytes)."""
    out = []
    for v in np.asarray(values).ravel():
        out.append(v.decode() if isinstance(v, bytes) else str(v))
    return np.array(out, dtype=object)


def _style_axes(ax, xlabel, ylabel, title=None):
    ax.set_xlabel(xlabel, fontsize=_LABEL)
    ax.set_ylabel(ylabel, fontsize=_LABEL)
    ax.tick_params(labelsize=_TICK)
    if title:
        ax.set_title(title, fontsize=_TITLE)


def _plain_ticks(axis):
    """No offset and no scientific notation on a linear axis ("440", not "4.4e2 + …")."""
    from matplotlib.ticker import ScalarFormatter

    f = ScalarFormatter(useOffset=False)
    f.set_scientific(False)
    axis.set_major_formatter(f)


def _legend_outside(ax, handles=None, labels=None, title=None):
    """A legend right of the axes, never on the curves."""
    kw = {}
    if handles is not None:
        kw["handles"] = handles
    if labels is not None:
        kw["labels"] = labels
    return ax.legend(
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        borderaxespad=0.0,
        fontsize=_LEGEND,
        title=title,
        title_fontsize=_LEGEND,
        frameon=False,
        **kw,
    )


def _gas(*attrs_texts):
    for t in attrs_texts:
        for g in _GASES:
            if re.search(rf"(?<![A-Za-z0-9]){g}(?![a-z0-9])", t or ""):
                return g
    return None


def _fraction_unit(units):
    return _FRACTION_UNITS.get(str(units), str(units))


def _robust_window(points, floor_frac=0.02, k=10.0):
    """A window [lo, hi] holding the bulk of ``points``: median ± k·(1.4826·MAD), at least
    ± floor_frac·|median|; a wild value (a DIAL cell with next to no signal) falls outside."""
    p = np.asarray(points, dtype=float)
    p = p[np.isfinite(p)]
    if p.size == 0:
        return -1.0, 1.0
    med = float(np.median(p))
    mad = 1.4826 * float(np.median(np.abs(p - med)))
    half = max(k * mad, floor_frac * abs(med), 1e-12)
    return med - half, med + half


def _limits(points, keep, errors_lo=(), errors_hi=(), floor_frac=0.02):
    """Axis limits from ``points`` (e.g. retrieved and truth): the robust window of the
    points, always holding the ``keep`` values (the truth), widened to hold error-bar ends that
    lie within one window span of it. Returns (lo, hi, inside) with ``inside`` a mask of
    ``points`` that lie within the limits."""
    pts = np.asarray(points, dtype=float)
    keep = np.asarray(keep, dtype=float)
    keep = keep[np.isfinite(keep)]
    w_lo, w_hi = _robust_window(np.concatenate([pts, keep]), floor_frac=floor_frac)
    if keep.size:
        w_lo, w_hi = min(w_lo, keep.min()), max(w_hi, keep.max())
    inside = np.isfinite(pts) & (pts >= w_lo) & (pts <= w_hi)
    vals = np.concatenate([pts[inside], keep])
    if vals.size == 0:
        return -1.0, 1.0, inside
    lo, hi = float(vals.min()), float(vals.max())
    span = max(hi - lo, floor_frac * max(abs(lo), abs(hi)), 1e-12)
    ends = np.concatenate(
        [np.asarray(errors_lo, dtype=float), np.asarray(errors_hi, dtype=float)]
    )
    ends = ends[np.isfinite(ends) & (ends >= lo - span) & (ends <= hi + span)]
    if ends.size:
        lo, hi = min(lo, float(ends.min())), max(hi, float(ends.max()))
    pad = 0.05 * max(hi - lo, 1e-9 * max(abs(lo), 1.0))
    return lo - pad, hi + pad, inside


# --- returns ------------------------------------------------------------------------------


def returns(ds, *, fov=None, source=None, orders=("total", "1"), ax=None):
    """Received energy per pulse against range, every channel and field of view.

    The Monte Carlo returns are drawn as solid lines with a band of ± one standard error,
    one line per scattering order in ``orders``; the analytic lidar equation (single
    scattering, its only order) as a dashed line of the same colour. The energy axis is
    logarithmic and keeps the eight decades below the largest return; where the standard
    error exceeds the value, the band's lower edge stops at a tenth of the value.

    Colours: with one channel, one colour per field of view; with one field of view, one per
    channel; with several of both and no ``ax`` given, one panel per field of view (colour per
    channel), else one colour per (channel, field of view). Colours come from the qualitative
    ``tab20`` map (``tab10`` up to ten curves), so up to 20 channels stay apart.

    Parameters
    ----------
    ds : xarray.Dataset
        A run: ``energy_j`` [J] and ``stderr_j`` [J] on (source, channel,
        fov_full_angle_mrad, range_m, order), ``range_m`` [m] the gate centres.
    fov : float or sequence of float, optional
        Fields of view to draw, full angle [mrad]; default all of them.
    source : {"mc", "analytic"} or sequence, optional
        Sources to draw; default all of them in ``ds``.
    orders : sequence of str
        Scattering orders of the Monte Carlo returns to draw (``"total"``, ``"1"``, …,
        ``"N+"``); orders ``ds`` does not hold are skipped. The analytic returns are drawn at
        order ``"1"`` whatever this says.
    ax : matplotlib.axes.Axes or sequence of Axes, optional
        One Axes: everything in it. A sequence with one Axes per field of view: one panel
        each. Default: a new figure.

    Returns
    -------
    matplotlib.axes.Axes or numpy.ndarray of Axes
        The Axes drawn into (an array when there is one panel per field of view).

    Raises
    ------
    ValueError
        If ``ds`` has no ``energy_j``, or ``fov``, ``source`` or ``orders`` select nothing.
    """
    _require(ds, ["energy_j", "range_m"], "returns")
    sources = _select(_text(ds["source"].values), source, "source")
    fovs_all = np.asarray(ds["fov_full_angle_mrad"].values, dtype=float)
    if fov is None:
        fovs = list(fovs_all)
    else:
        want = np.atleast_1d(np.asarray(fov, dtype=float))
        fovs = [f for f in fovs_all if np.any(np.isclose(f, want))]
        if not fovs:
            raise ValueError(
                f"returns: no field of view {list(want)} mrad in this run "
                f"(it has {list(fovs_all)} mrad)"
            )
    channels = list(_text(ds["channel"].values))
    ds_orders = list(_text(ds["order"].values))
    mc_orders = [o for o in orders if o in ds_orders]
    if "mc" in sources and not mc_orders:
        raise ValueError(
            f"returns: none of the orders {list(orders)} is in this run (it has {ds_orders})"
        )
    has_err = "stderr_j" in ds.variables

    # Panels.
    nch, nfov = len(channels), len(fovs)
    if ax is None:
        if nch > 1 and nfov > 1:
            plt = _pyplot()
            ncol = min(nfov, 3)
            nrow = -(-nfov // ncol)
            fig, axs = plt.subplots(
                nrow,
                ncol,
                figsize=(4.6 * ncol + 2.6, 4.2 * nrow),
                sharex=True,
                sharey=True,
                layout="constrained",
                squeeze=False,
            )
            axs = axs.ravel()
            for extra in axs[nfov:]:
                extra.set_visible(False)
            axes = list(axs[:nfov])
        else:
            axes = [_new_axes((9.5, 5.5))]
    elif np.ndim(ax) == 0 and not isinstance(ax, (list, tuple)):
        axes = [ax]
    else:
        axes = list(np.ravel(ax))
        if len(axes) != nfov:
            raise ValueError(
                f"returns: {len(axes)} Axes given for {nfov} fields of view; give one Axes, "
                "or one per field of view"
            )
    per_fov_panels = len(axes) > 1

    # Colours.
    if per_fov_panels or nfov == 1:
        keys = [(c,) for c in channels]
    elif nch == 1:
        keys = [(f,) for f in fovs]
    else:
        keys = [(c, f) for c in channels for f in fovs]
    cmap = _pyplot().get_cmap("tab10" if len(keys) <= 10 else "tab20")
    colour = {k: cmap(i % cmap.N) for i, k in enumerate(keys)}

    def key(c, f):
        if per_fov_panels or nfov == 1:
            return (c,)
        if nch == 1:
            return (f,)
        return (c, f)

    def name(k):
        parts = []
        for p in k:
            parts.append(f"{p:g} mrad" if isinstance(p, (float, np.floating)) else str(p))
        return ", ".join(parts)

    r_km = np.asarray(ds["range_m"].values, dtype=float) / 1000.0
    # Which orders each source draws, and their line styles: Monte Carlo solid, the next
    # orders dash-dotted and dotted; analytic dashed.
    mc_styles = ["-", "-.", ":", (0, (5, 1, 1, 1, 1, 1))]
    drawn = []  # (source, order)
    for s in sources:
        for o in mc_orders if s == "mc" else ["1"]:
            if o in ds_orders:
                drawn.append((s, o))
    style = {}
    i_mc = 0
    for s, o in drawn:
        if s == "mc":
            style[(s, o)] = mc_styles[i_mc % len(mc_styles)]
            i_mc += 1
        else:
            style[(s, o)] = "--"

    top = -np.inf
    positives = []
    for ia, a in enumerate(axes):
        panel_fovs = [fovs[ia]] if per_fov_panels else fovs
        for c in channels:
            for f in panel_fovs:
                for s, o in drawn:
                    sel = dict(source=s, channel=c, fov_full_angle_mrad=f, order=o)
                    e = np.asarray(ds["energy_j"].sel(sel).values, dtype=float)
                    ok = np.isfinite(e) & (e > 0)
                    if not ok.any():
                        continue
                    y = np.where(ok, e, np.nan)
                    col = colour[key(c, f)]
                    (line,) = a.plot(
                        r_km,
                        y,
                        color=col,
                        linestyle=style[(s, o)],
                        linewidth=1.6 if s == "mc" else 1.3,
                        label=f"{name(key(c, f))}, {s}, order {o}",
                    )
                    line.lidarsim_series = (s, c, float(f), o)
                    if s == "mc" and has_err:
                        se = np.asarray(ds["stderr_j"].sel(sel).values, dtype=float)
                        se = np.where(np.isfinite(se), se, 0.0)
                        # On a log axis a band down to e − se ≤ 0 would reach the bottom:
                        # its lower edge stops at a tenth of the value.
                        lo = np.where(ok, np.maximum(e - se, 0.1 * e), np.nan)
                        hi = np.where(ok, e + se, np.nan)
                        a.fill_between(r_km, lo, hi, color=col, alpha=0.25, linewidth=0)
                    top = max(top, float(np.nanmax(y)))
                    positives.append(float(np.nanmin(y)))
    if not positives:
        raise ValueError("returns: no positive energy to draw for this selection")
    bottom = max(min(positives), top * 1e-8) / 1.5
    for ia, a in enumerate(axes):
        a.set_yscale("log")
        a.set_ylim(bottom, top * 2.0)
        a.set_xlim(r_km.min(), r_km.max())
        _plain_ticks(a.xaxis)
        a.grid(True, which="major", alpha=0.3)
        title = None
        if per_fov_panels:
            title = f"FOV {fovs[ia]:g} mrad"
        elif nfov == 1:
            title = f"received energy per pulse, FOV {fovs[0]:g} mrad"
        else:
            title = "received energy per pulse"
        _style_axes(
            a,
            "range [km]",
            "energy per gate [J]" if (ia % min(len(axes), 3) == 0) else "",
            title,
        )
    if per_fov_panels:
        axes[0].figure.suptitle("received energy per pulse", fontsize=_TITLE + 1)

    # One legend: the colours (channel / FOV), then the line styles (source, order).
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = []
    used = {key(c, f) for c in channels for f in fovs}
    for k in keys:
        if k in used:
            handles.append(Line2D([], [], color=colour[k], linewidth=2.5, label=name(k)))
    for s, o in drawn:
        lab = (
            "analytic, single scattering"
            if s == "analytic"
            else ("Monte Carlo, all orders" if o == "total" else f"Monte Carlo, order {o}")
        )
        handles.append(
            Line2D([], [], color="0.2", linestyle=style[(s, o)], linewidth=1.6, label=lab)
        )
    if "mc" in sources and has_err:
        handles.append(Patch(color="0.2", alpha=0.25, label="± 1 standard error"))
    _legend_outside(axes[-1] if per_fov_panels else axes[0], handles=handles)
    return np.array(axes, dtype=object) if per_fov_panels else axes[0]


def _select(have, want, what):
    have = list(have)
    if want is None:
        return have
    want = [want] if isinstance(want, str) else list(want)
    out = [h for h in have if h in want]
    if not out:
        raise ValueError(f"returns: no {what} {want} in this run (it has {have})")
    return out
