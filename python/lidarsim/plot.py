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

__all__ = ["returns", "retrieval", "study_errors", "study_budget", "budget_table"]

# Font sizes fit for a slide (points).
_LABEL = 12
_TICK = 11
_TITLE = 12
_LEGEND = 10

# Colours of the kinds of returns a retrieval used, as the CLI draws them (analytic blue,
# Monte Carlo red); Monte Carlo single scattering in between.
_KIND_COLOUR = {
    ("analytic", "1st"): "tab:blue",
    ("mc", "total"): "tab:red",
    ("mc", "1st"): "tab:orange",
}
_KIND_LABEL = {
    ("analytic", "1st"): "analytic, single scattering",
    ("mc", "total"): "Monte Carlo, all orders",
    ("mc", "1st"): "Monte Carlo, single scattering",
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


def _cmap(name):
    import matplotlib

    return matplotlib.colormaps[name]


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
    if handles is None:
        handles, labels = ax.get_legend_handles_labels()
        # The truth first, the rest in drawing order.
        order = sorted(range(len(labels)), key=lambda i: not labels[i].startswith("truth"))
        handles = [handles[i] for i in order]
        labels = [labels[i] for i in order]
        kw = {"handles": handles, "labels": labels}
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
    ± floor_frac·|median| (where the MAD is below that, up to 1.5 × the 10–90 % percentile
    range, at most three times it); a wild value (a DIAL cell with next to no signal) falls
    outside."""
    p = np.asarray(points, dtype=float)
    p = p[np.isfinite(p)]
    if p.size == 0:
        return -1.0, 1.0
    med = float(np.median(p))
    mad = 1.4826 * float(np.median(np.abs(p - med)))
    floor = floor_frac * abs(med)
    half = max(k * mad, floor, 1e-12)
    if k * mad < floor:
        # Most values coincide (noise-free cells equal to a well-mixed truth), so the MAD is
        # ~0: the central 80 % of the points, widened by half, keeps the noisy cells in view,
        # up to three times the floor.
        spread = 1.5 * float(np.percentile(p, 90) - np.percentile(p, 10))
        half = max(half, min(spread, 3.0 * floor))
    return med - half, med + half


def _limits(points, keep, half_widths=(), floor_frac=0.02, bar_cap=0.0):
    """Axis limits from ``points`` (the retrieved values), ``keep`` (the truth, always
    inside) and the error bars' ``half_widths`` (one per point).

    The limits hold the robust window of the points (:func:`_robust_window`) and every error
    bar no longer than the span of the values (at least ``floor_frac`` of their size) or than
    ``bar_cap``. Returns
    (lo, hi, inside) with ``inside`` the mask of ``points`` within the limits."""
    pts = np.asarray(points, dtype=float)
    keep = np.asarray(keep, dtype=float)
    keep = keep[np.isfinite(keep)]
    # The window from the retrieved points alone: truths that coincide (a well-mixed CO2
    # gives every cell the same truth) would otherwise narrow it to nothing.
    w_lo, w_hi = _robust_window(pts if np.isfinite(pts).any() else keep, floor_frac=floor_frac)
    if keep.size:
        w_lo, w_hi = min(w_lo, keep.min()), max(w_hi, keep.max())
    inside = np.isfinite(pts) & (pts >= w_lo) & (pts <= w_hi)
    vals = np.concatenate([pts[inside], keep])
    if vals.size == 0:
        return -1.0, 1.0, inside
    lo, hi = float(vals.min()), float(vals.max())
    span = max(hi - lo, floor_frac * max(abs(lo), abs(hi)), 1e-12)
    hw = np.asarray(half_widths, dtype=float)
    if hw.size:
        fit = inside & np.isfinite(hw) & (hw <= max(span, bar_cap))
        if fit.any():
            lo = min(lo, float(np.min(pts[fit] - hw[fit])))
            hi = max(hi, float(np.max(pts[fit] + hw[fit])))
    pad = 0.05 * max(hi - lo, 1e-9 * max(abs(lo), 1.0))
    return lo - pad, hi + pad, inside


# --- returns ------------------------------------------------------------------------------


def returns(ds, *, fov=None, source=None, orders=("total", "1st"), ax=None):
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
        Scattering orders of the Monte Carlo returns to draw (``"total"``, ``"1st"``,
        ``"2nd"``, …, ``"6th+"``); orders ``ds`` does not hold are skipped. The analytic
        returns are drawn at order ``"1st"`` whatever this says.
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
    cmap = _cmap("tab10" if len(keys) <= 10 else "tab20")
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
        for o in mc_orders if s == "mc" else ["1st"]:
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
                        label=f"{name(key(c, f))}, {s}, {o} order",
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
            else ("Monte Carlo, all orders" if o == "total" else f"Monte Carlo, {o} order")
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


# --- retrieval ----------------------------------------------------------------------------

_MR = "mixing_ratio_"
_DIAL_METHODS = ("dial",)


def _products(ds):
    """The mixing-ratio rows of a run's retrieval as a dict of 1-D numpy arrays."""
    if _MR + "retrieved" not in ds.variables:
        raise ValueError(
            "retrieval: this run has no retrieval (no [retrieval] in its scene, so no "
            "'mixing_ratio_retrieved'): nothing to draw"
        )
    cols = [
        "method",
        "source",
        "order",
        "channel_pair",
        "fov_full_angle_mrad",
        "altitude_bottom_m",
        "altitude_top_m",
        "truth",
        "retrieved",
    ]
    _require(ds, [_MR + c for c in cols], "retrieval")
    out = {}
    for c in cols:
        v = ds[_MR + c].values
        out[c] = _text(v) if v.dtype.kind in "OSU" else np.asarray(v, dtype=float)
    return out


def retrieval(ds, *, method=None, fov=None, error="random_error_averaged", ax=None):
    """Retrieved dry-air mixing ratio against the truth, as the CLI's ``dial.png``.

    DIAL (range-resolved): the retrieved mixing ratio of every cell against altitude, with
    its error as a horizontal error bar, beside the truth (the cell averages, a black
    staircase); one colour per kind of returns (analytic single scattering, Monte Carlo
    single scattering, Monte Carlo all orders; per line pair too if there are several), one
    marker per field of view. IPDA (one column per field of view, kind and pair): the
    column-averaged mixing ratio (XCO2) as a point with its error bar, the truth as a black
    dash above the same slot.

    The mixing-ratio axis is set by the values and the truth, robustly: a cell far off the
    rest (a far DIAL cell with next to no signal) is drawn as an arrow at the edge, and error
    bars much longer than the spread of the values run off the axis; the title says so in
    both cases.

    Parameters
    ----------
    ds : xarray.Dataset
        A run with a retrieval: the ``mixing_ratio_*`` variables on ``mixing_ratio_product``
        (truth and retrieved in the unit of their ``units`` attribute, ``1e-6`` = ppm;
        altitudes [m]; field of view full angle [mrad]).
    method : {"dial", "ipda", "ipda_virtual_sigma"}, optional
        What to draw. Default: the DIAL cells if the run has any, else the IPDA columns.
    fov : float or sequence of float, optional
        Fields of view [mrad] to draw; default all of them.
    error : str
        The error bar: ``random_error_averaged`` (default, as the CLI: the analytic random
        error after averaging the shot pairs), ``random_error_per_shot_pair``, ``mc_stderr``,
        ``simulated_error_averaged``, … (any ``mixing_ratio_<error>`` of ``ds``), or None.
    ax : matplotlib.axes.Axes, optional
        Where to draw; default a new figure.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    ValueError
        If the run has no retrieval, or no row of ``method`` and ``fov``.
    """
    p = _products(ds)
    methods = list(dict.fromkeys(p["method"]))
    if method is None:
        method = "dial" if "dial" in methods else next(
            (m for m in methods if m.startswith("ipda")), methods[0] if methods else None
        )
    pick = p["method"] == method
    if fov is not None:
        want = np.atleast_1d(np.asarray(fov, dtype=float))
        pick &= np.isclose(p["fov_full_angle_mrad"][:, None], want[None, :]).any(axis=1)
    if not pick.any():
        raise ValueError(
            f"retrieval: no {method!r} rows"
            + (f" at FOV {list(np.atleast_1d(fov))} mrad" if fov is not None else "")
            + f" in this run (its methods: {methods}, FOVs: "
            f"{sorted(set(p['fov_full_angle_mrad'].tolist()))} mrad)"
        )
    if error is not None:
        _require(ds, [_MR + error], "retrieval (error bars)")
        err = np.asarray(ds[_MR + error].values, dtype=float)
    else:
        err = np.zeros_like(p["retrieved"])
    err = np.where(np.isfinite(err), np.abs(err), 0.0)
    rows = {k: v[pick] for k, v in p.items()}
    rows["error"] = err[pick]
    unit = _fraction_unit(ds[_MR + "retrieved"].attrs.get("units", "1e-6"))
    gas = _gas(
        ds[_MR + "truth"].attrs.get("standard_name", "").replace(
            "carbon_dioxide", "CO2"
        ).replace("methane", "CH4"),
        ds[_MR + "truth"].attrs.get("long_name", ""),
    )
    if ax is None:
        ax = _new_axes((9.0, 6.5) if method == "dial" else (9.0, 5.5))
    if method == "dial":
        _dial_cells(ax, rows, gas, unit, error)
    else:
        _ipda_columns(ax, rows, gas, unit, error, method)
    return ax


def _kinds(rows):
    kinds = list(dict.fromkeys(zip(rows["source"], rows["order"])))
    order = list(_KIND_COLOUR)
    kinds.sort(key=lambda k: order.index(k) if k in order else len(order))
    return kinds


def _kind_label(k):
    return _KIND_LABEL.get(k, f"{k[0]}, {k[1]} order")


def _series_colours(pairs, kinds):
    if len(pairs) == 1:
        return {(pairs[0], k): _KIND_COLOUR.get(k, "tab:purple") for k in kinds}
    cmap = _cmap("tab10" if len(pairs) * len(kinds) <= 10 else "tab20")
    keys = [(pr, k) for pr in pairs for k in kinds]
    return {key: cmap(i % cmap.N) for i, key in enumerate(keys)}


def _draw_points(ax, x, y, err, lo, hi, inside, colour, marker, horizontal, label,
                 hollow=False):
    """Points with error bars; error bars that run off the axis [lo, hi] drawn faint and
    without caps, points off the axis as arrows at its edge. Returns (points off the axis,
    error bars off the axis)."""
    v = x if horizontal else y
    fits = inside & (v - err >= lo) & (v + err <= hi)
    long_ = inside & ~fits
    for m, kw in ((fits, dict(alpha=1.0, capsize=3, elinewidth=1.2)),
                  (long_, dict(alpha=0.3, capsize=0, elinewidth=0.8))):
        if m.any():
            e = err[m]
            c = ax.errorbar(x[m], y[m], xerr=e if horizontal else None,
                            yerr=None if horizontal else e, fmt="none", ecolor=colour, **kw)
            c.lidarsim_role = "error"
    if inside.any():
        (pts,) = ax.plot(x[inside], y[inside], marker=marker, color=colour, markersize=6,
                         linestyle="none", label=label, zorder=3,
                         markerfacecolor="white" if hollow else colour)
        pts.lidarsim_role = "retrieved"
        label = None
    out = ~inside & np.isfinite(v)
    if out.any():
        above = v[out] > hi
        edge = np.where(above, hi, lo)
        xs, ys = (edge, y[out]) if horizontal else (x[out], edge)
        for xx, yy, up in zip(xs, ys, above):
            mk = (">" if up else "<") if horizontal else ("^" if up else "v")
            (a,) = ax.plot([xx], [yy], marker=mk, color=colour, markersize=9,
                           linestyle="none", clip_on=False, label=label, zorder=3,
                           markerfacecolor="white" if hollow else colour)
            a.lidarsim_role = "off-scale"
            label = None
    return int(out.sum()), int(long_.sum())


def _off_scale_note(n_points, n_bars, what, longest, unit):
    notes = []
    if n_points:
        notes.append(f"{n_points} {what} off-scale (arrows)")
    if n_bars:
        notes.append(f"{n_bars} error bars run off the axis (faint; up to ±{longest:.3g} {unit})")
    return "; ".join(notes)


def _dial_cells(ax, rows, gas, unit, error):
    z_mid = 0.5 * (rows["altitude_bottom_m"] + rows["altitude_top_m"]) / 1000.0
    height = np.median(rows["altitude_top_m"] - rows["altitude_bottom_m"]) / 1000.0
    x, e, t = rows["retrieved"], rows["error"], rows["truth"]
    lo_x, hi_x, inside = _limits(x, t, e)
    pairs = list(dict.fromkeys(rows["channel_pair"]))
    kinds = _kinds(rows)
    fovs = sorted(set(rows["fov_full_angle_mrad"].tolist()))
    colours = _series_colours(pairs, kinds)
    series = [(pr, k, f) for pr in pairs for k in kinds for f in fovs]
    n = len(series)
    n_off = n_bars = 0
    for i, (pr, k, f) in enumerate(series):
        m = (
            (rows["channel_pair"] == pr)
            & (rows["source"] == k[0])
            & (rows["order"] == k[1])
            & (rows["fov_full_angle_mrad"] == f)
            & np.isfinite(x)
        )
        if not m.any():
            continue
        # Series side by side within a cell, so that equal values stay visible.
        dz = (i - (n - 1) / 2) * min(0.5 * height / max(n, 1), 0.08 * height)
        label = _kind_label(k)
        if len(pairs) > 1:
            label = f"{pr}: {label}"
        if len(fovs) > 1:
            label += f", FOV {f:g} mrad"
        xi, ei, zi, ins = x[m], e[m], z_mid[m] + dz, inside[m]
        off, bars = _draw_points(
            ax, xi, zi, ei, lo_x, hi_x, ins, colours[(pr, k)],
            _FOV_MARKERS[fovs.index(f) % len(_FOV_MARKERS)], True, label,
        )
        n_off += off
        n_bars += bars
    # The truth: one staircase per distinct truth profile (per pair, usually the same).
    drew_truth = set()
    for pr in pairs:
        m = (rows["channel_pair"] == pr) & np.isfinite(t)
        cells = sorted(
            set(zip(rows["altitude_bottom_m"][m], rows["altitude_top_m"][m], t[m]))
        )
        sig = tuple(cells)
        if not cells or sig in drew_truth:
            continue
        drew_truth.add(sig)
        xs, zs = [], []
        prev_top = None
        for b, tp, v in cells:
            if prev_top is not None and not np.isclose(b, prev_top):
                xs.append(np.nan)
                zs.append(np.nan)
            xs += [v, v]
            zs += [b / 1000.0, tp / 1000.0]
            prev_top = tp
        (line,) = ax.plot(
            xs, zs, color="black", linewidth=2.0,
            label="truth (cell averages)" if not len(drew_truth) > 1 else None,
        )
        line.lidarsim_role = "truth"
    ax.set_xlim(lo_x, hi_x)
    z_lo = rows["altitude_bottom_m"].min() / 1000.0
    z_hi = rows["altitude_top_m"].max() / 1000.0
    ax.set_ylim(z_lo - 0.02 * (z_hi - z_lo), z_hi + 0.02 * (z_hi - z_lo))
    _plain_ticks(ax.xaxis)
    _plain_ticks(ax.yaxis)
    ax.grid(True, alpha=0.3)
    g = gas or "gas"
    title = f"DIAL {g}" + (f", {pairs[0]}" if len(pairs) == 1 else "")
    title += f", ± {error.replace('_', ' ')}" if error else ""
    note = _off_scale_note(n_off, n_bars, "cells", np.max(e[np.isfinite(x)], initial=0), unit)
    n_empty = int(np.sum(~np.isfinite(x)))
    if n_empty:
        empty = f"{n_empty} cells without a value (too little signal)"
        note = f"{note}; {empty}" if note else empty
    _style_axes(
        ax,
        f"{g} dry-air mixing ratio [{unit}]",
        "altitude [km]",
        title + ("\n" + note if note else ""),
    )
    _legend_outside(ax)


def _ipda_columns(ax, rows, gas, unit, error, method):
    # One slot per row, grouped by pair and field of view.
    pairs = list(dict.fromkeys(rows["channel_pair"]))
    kinds = _kinds(rows)
    fovs = sorted(set(rows["fov_full_angle_mrad"].tolist()))
    colours = _series_colours(pairs, kinds)
    x, e, t = rows["retrieved"], rows["error"], rows["truth"]
    lo_y, hi_y, inside = _limits(x, t, e, floor_frac=0.01)
    slots, ticks, labels = [], [], []
    pos = 0.0
    for pr in pairs:
        for f in fovs:
            group = []
            for k in kinds:
                m = np.flatnonzero(
                    (rows["channel_pair"] == pr)
                    & (rows["fov_full_angle_mrad"] == f)
                    & (rows["source"] == k[0])
                    & (rows["order"] == k[1])
                )
                for i in m:
                    group.append((pos, i, k, pr))
                    pos += 1.0
            if group:
                slots += group
                ticks.append(np.mean([g[0] for g in group]))
                labels.append(f"FOV {f:g} mrad" + (f"\n{pr}" if len(pairs) > 1 else ""))
                pos += 0.6
    seen = set()
    n_off = n_bars = 0
    for xpos, i, k, pr in slots:
        key = (pr, k)
        lab = None if key in seen else (
            (f"{pr}: " if len(pairs) > 1 else "") + _kind_label(k)
        )
        seen.add(key)
        off, bars = _draw_points(
            ax, np.array([xpos]), np.array([x[i]]), np.array([e[i]]), lo_y, hi_y,
            np.array([inside[i]]), colours[key], "o", False, lab,
        )
        n_off += off
        n_bars += bars
        tr = ax.plot([xpos], [t[i]], marker="_", markersize=28, markeredgewidth=2.5,
                     color="black", linestyle="none",
                     label="truth" if xpos == slots[0][0] else None)
        tr[0].lidarsim_role = "truth"
    ax.set_xticks(ticks)
    ax.set_xticklabels(labels)
    ax.set_xlim(-0.7, pos - 0.6 + 0.1)
    ax.set_ylim(lo_y, hi_y)
    _plain_ticks(ax.yaxis)
    ax.grid(True, axis="y", alpha=0.3)
    g = gas or "gas"
    what = "IPDA" if method == "ipda" else method.replace("_", " ").replace("ipda", "IPDA")
    title = f"{what} column X{g}" + (f", {pairs[0]}" if len(pairs) == 1 else "")
    title += f", ± {error.replace('_', ' ')}" if error else ""
    note = _off_scale_note(n_off, n_bars, "columns", np.max(e[np.isfinite(x)], initial=0), unit)
    _style_axes(ax, "", f"X{g} [{unit}]", title + ("\n" + note if note else ""))
    _legend_outside(ax)


# --- dial study ---------------------------------------------------------------------------

_CLASS_ORDER = ["tropical", "mid", "high", "all"]
# Columns of profiles.nc that are not error-budget rows.
_NOT_BUDGET = {
    "truth_ppm",
    "retrieved_ppm",
    "error_ppm",
    "retrieved_noisy_ppm",
    "error_noisy_ppm",
    "retrieved_own_profile_ppm",
}


def _flat(ds, da):
    """A variable of a study's file as a flat array in the order of ``_table``: a table on
    ``row`` as it is; on (profile or class, pair, retrieval), ``profiles.nc`` and
    ``summary.nc``, broadcast to those dimensions and raveled."""
    if "row" in ds.dims:
        return da.values
    order = [d for d in ("profile", "class", "pair", "retrieval") if d in ds.dims]
    full = da.variable.set_dims({d: ds.sizes[d] for d in order})
    return full.transpose(*order).values.ravel()


def _table(ds, names, what):
    """Columns of a study's file as flat arrays: the variables ``names`` (``profile_id`` is the
    coordinate ``profile`` of ``profiles.nc``); on (profile or class, pair, retrieval), the
    cells no record fills (every value missing) left out."""
    names = list(names)
    alias = {"profile_id": "profile"} if "row" not in ds.dims and "profile_id" not in ds.variables else {}
    # A missing column is named as the caller asked for it.
    alias = {k: v for k, v in alias.items() if v in ds.variables}
    _require(ds, [alias.get(n, n) for n in names], what)
    out = {}
    for n in names:
        v = _flat(ds, ds[alias.get(n, n)])
        out[n] = _text(v) if v.dtype.kind in "OSU" else np.asarray(v, dtype=float)
    if "row" not in ds.dims:
        keep = _filled(ds)
        out = {k: v[keep] for k, v in out.items()}
    return out


def _filled(ds):
    """The cells of a study's arrays that hold a record (any number there)."""
    numbers = [v for v in ds.data_vars if ds[v].dtype.kind == "f"]
    keep = None
    for v in numbers:
        k = np.isfinite(np.asarray(_flat(ds, ds[v]), dtype=float))
        keep = k if keep is None else keep | k
    return keep


def _pick_method(methods, method, what):
    if method is None:
        method = "ipda" if "ipda" in methods else (methods[0] if methods else None)
    if method not in methods:
        raise ValueError(f"{what}: no {method!r} rows in this table (methods: {methods})")
    return method


def _pair_names(pairs):
    """On-line names alone when every pair shares one off-line, with that off-line."""
    offs = {p.rsplit("/", 1)[-1] for p in pairs if "/" in p}
    if len(offs) == 1 and all("/" in p for p in pairs) and len(pairs) > 1:
        return [p.rsplit("/", 1)[0] for p in pairs], f"on-line (off-line {offs.pop()})"
    return list(pairs), "line pair (on/off)"


def study_errors(summary, *, method=None, group=None, ax=None):
    """Bias and spread of a ``lidarsim dial`` study's retrievals, per latitude class and line
    pair, with and without instrument noise.

    Each point is the mean of retrieved − true over the profiles of a class (``all``: every
    profile), its error bar the standard deviation over them: filled markers for the
    noise-free retrievals (``bias_ppm`` ± ``sd_ppm``), open markers for one noisy
    measurement per profile (``noisy_bias_ppm`` ± ``noisy_sd_ppm``). IPDA: one slot per line
    pair, one colour per class. DIAL: the cells against altitude, one colour per line pair
    (class ``all`` unless ``group`` says otherwise). Values far off the rest (a noisy DIAL
    cell with next to no signal) are drawn as arrows at the edge, and the title says so.

    Parameters
    ----------
    summary : xarray.Dataset
        ``summary.nc`` of ``lidarsim dial``: arrays on (class, pair, retrieval) with the
        coordinates ``class``, ``pair``, ``method``, ``bias_ppm``, ``sd_ppm``, ``noisy_bias_ppm``, ``noisy_sd_ppm``
        [ppm] and ``altitude_bottom_m``, ``altitude_top_m`` [m].
    method : {"ipda", "dial"}, optional
        Default ``ipda`` if the study has it, else ``dial``.
    group : str or sequence of str, optional
        Latitude classes to draw (``tropical``, ``mid``, ``high``, ``all``). Default: every
        class for IPDA, ``all`` (or the one class) for DIAL.
    ax : matplotlib.axes.Axes, optional
        Where to draw; default a new figure.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    ValueError
        If a column is missing, or no row has ``method`` and ``group``.
    """
    cols = ["class", "pair", "method", "bias_ppm", "sd_ppm", "noisy_bias_ppm", "noisy_sd_ppm",
            "altitude_bottom_m", "altitude_top_m"]
    t = _table(summary, cols, "study_errors (summary.nc of lidarsim dial)")
    method = _pick_method(list(dict.fromkeys(t["method"])), method, "study_errors")
    classes = [c for c in dict.fromkeys(t["class"])]
    classes.sort(key=lambda c: _CLASS_ORDER.index(c) if c in _CLASS_ORDER else 99)
    if group is None:
        groups = classes if method == "ipda" else (["all"] if "all" in classes else classes[:1])
    else:
        groups = [group] if isinstance(group, str) else list(group)
    m = (t["method"] == method) & np.isin(t["class"], groups)
    if not m.any():
        raise ValueError(
            f"study_errors: no {method!r} rows of class {groups} (classes: {classes})"
        )
    r = {k: v[m] for k, v in t.items()}
    pairs = list(dict.fromkeys(r["pair"]))
    names, pair_axis = _pair_names(pairs)
    gas = _gas(summary["truth_mean_ppm"].attrs.get("long_name", "")) if "truth_mean_ppm" in summary.variables else None
    g = gas or "gas"
    unit = _fraction_unit(summary["bias_ppm"].attrs.get("units", "1e-6"))
    if ax is None:
        ax = _new_axes((9.5, 5.5) if method == "ipda" else (9.0, 6.5))
    values = np.concatenate([r["bias_ppm"], r["noisy_bias_ppm"]])
    halfs = np.concatenate([np.nan_to_num(r["sd_ppm"]), np.nan_to_num(r["noisy_sd_ppm"])])
    # The spread is what this figure shows: every error bar fits but one far longer than the
    # typical (ten times the median), which a noisy far DIAL cell gives.
    typical = halfs[np.isfinite(halfs) & (halfs > 0)]
    cap = 10.0 * float(np.median(typical)) if typical.size else 0.0
    lo, hi, inside = _limits(values, [0.0], halfs, floor_frac=0.0, bar_cap=cap)
    if not (hi - lo > 0):
        lo, hi = -1.0, 1.0
    n = len(r["bias_ppm"])
    in_clean, in_noisy = inside[:n], inside[n:]
    n_off = n_bars = 0
    cmap = _cmap("tab10")
    if method == "ipda":
        gs = [c for c in groups if c in set(r["class"])]
        width = 0.8 / max(len(gs), 1)
        for j, c in enumerate(gs):
            colour = _CLASS_COLOUR.get(c, cmap(j % 10))
            for noisy in (False, True):
                sel = r["class"] == c
                xs = np.array([pairs.index(p) for p in r["pair"][sel]], dtype=float)
                xs += (j - (len(gs) - 1) / 2) * width + (0.12 * width if noisy else -0.12 * width)
                b = r["noisy_bias_ppm" if noisy else "bias_ppm"][sel]
                e = np.nan_to_num(r["noisy_sd_ppm" if noisy else "sd_ppm"][sel])
                ins = (in_noisy if noisy else in_clean)[sel]
                off, bars = _draw_points(
                    ax, xs, b, e, lo, hi, ins, colour, "s" if noisy else "o", False,
                    f"{c}, {'one noisy measurement' if noisy else 'noise-free'}",
                    hollow=noisy,
                )
                n_off += off
                n_bars += bars
        ax.axhline(0.0, color="0.4", linewidth=1.0, linestyle="--", zorder=0)
        ax.set_xticks(range(len(pairs)))
        ax.set_xticklabels(names, rotation=30 if len(pairs) > 4 else 0,
                           ha="right" if len(pairs) > 4 else "center")
        ax.set_xlim(-0.6, len(pairs) - 0.4)
        ax.set_ylim(lo, hi)
        _plain_ticks(ax.yaxis)
        ax.grid(True, axis="y", alpha=0.3)
        xlabel, ylabel = pair_axis, f"retrieved − true X{g} [{unit}]"
        title = f"IPDA X{g} error by class and line pair (mean ± sd over profiles)"
    else:
        z = 0.5 * (r["altitude_bottom_m"] + r["altitude_top_m"]) / 1000.0
        height = float(np.median(r["altitude_top_m"] - r["altitude_bottom_m"])) / 1000.0
        keys = [(c, p) for c in groups for p in pairs]
        k_i = 0
        for c in groups:
            for p in pairs:
                sel = (r["class"] == c) & (r["pair"] == p)
                if not sel.any():
                    continue
                colour = cmap(k_i % 10) if len(keys) > 1 else "tab:blue"
                dz = (k_i - (len(keys) - 1) / 2) * min(0.4 * height / len(keys), 0.1 * height)
                k_i += 1
                for noisy in (False, True):
                    b = r["noisy_bias_ppm" if noisy else "bias_ppm"][sel]
                    e = np.nan_to_num(r["noisy_sd_ppm" if noisy else "sd_ppm"][sel])
                    ins = (in_noisy if noisy else in_clean)[sel]
                    zz = z[sel] + dz + (0.15 * height if noisy else 0.0) / max(len(keys), 1)
                    label = (f"{c}, " if len(groups) > 1 else "") + (
                        f"{names[pairs.index(p)]}, " if len(pairs) > 1 else "") + (
                        "one noisy measurement" if noisy else "noise-free")
                    off, bars = _draw_points(ax, b, zz, e, lo, hi, ins, colour,
                                             "s" if noisy else "o", True, label,
                                             hollow=noisy)
                    n_off += off
                    n_bars += bars
        ax.axvline(0.0, color="0.4", linewidth=1.0, linestyle="--", zorder=0)
        ax.set_xlim(lo, hi)
        _plain_ticks(ax.xaxis)
        _plain_ticks(ax.yaxis)
        ax.grid(True, alpha=0.3)
        xlabel, ylabel = f"retrieved − true {g} [{unit}]", "altitude [km]"
        title = (f"DIAL {g} error per cell, class {', '.join(groups)}"
                 + (f", {pairs[0]}" if len(pairs) == 1 else "")
                 + " (mean ± sd over profiles)")
    longest = float(np.nanmax(halfs)) if np.isfinite(halfs).any() else 0.0
    note = _off_scale_note(n_off, n_bars, "values", longest, unit)
    _style_axes(ax, xlabel, ylabel, title + ("\n" + note if note else ""))
    _legend_outside(ax)
    return ax


def budget_table(profiles, *, method="ipda"):
    """The error budget of a ``lidarsim dial`` study from its per-profile table, as
    ``budget.csv`` computes it: per latitude class (and ``all``), line pair and cell, for every
    budget row the rms over the profiles, sqrt(mean² + sd²) with the sample standard deviation
    (the ``random`` row: the rms of the random errors).

    Parameters
    ----------
    profiles : xarray.Dataset
        ``profiles.nc`` of ``lidarsim dial``: ``class``, ``pair``, ``method``,
        ``altitude_bottom_m`` [m] and one ``<source>_ppm`` column [ppm] per budget row.
    method : {"ipda", "dial"}

    Returns
    -------
    dict
        ``{(class, pair, altitude_bottom_m): {source: rms [ppm]}}``, classes including
        ``all``.
    """
    t = _table(profiles, ["profile_id", "class", "pair", "method", "altitude_bottom_m"],
               "study_budget (profiles.nc of lidarsim dial)")
    sources = [str(v)[: -len("_ppm")] for v in profiles.data_vars
               if str(v).endswith("_ppm") and str(v) not in _NOT_BUDGET]
    if not sources:
        raise ValueError(
            "study_budget: the table has no budget columns (<source>_ppm besides "
            f"{sorted(_NOT_BUDGET)}): is it profiles.nc of lidarsim dial?"
        )
    keep = _filled(profiles) if "row" not in profiles.dims else slice(None)
    vals = {s: np.asarray(_flat(profiles, profiles[s + "_ppm"]), dtype=float)[keep] for s in sources}
    m = t["method"] == method
    if not m.any():
        raise ValueError(
            f"study_budget: no {method!r} rows (methods: {sorted(set(t['method']))})"
        )
    out = {}
    classes = list(dict.fromkeys(t["class"][m])) + ["all"]
    for c in classes:
        for p in dict.fromkeys(t["pair"][m]):
            for zb in dict.fromkeys(t["altitude_bottom_m"][m].tolist()):
                sel = m & (t["pair"] == p) & (t["altitude_bottom_m"] == zb)
                if c != "all":
                    sel &= t["class"] == c
                row = {}
                for s in sources:
                    x = vals[s][sel]
                    x = x[np.isfinite(x)]
                    if x.size == 0:
                        continue
                    if s == "random":
                        row[s] = float(np.sqrt(np.mean(x**2)))
                    else:
                        sd = float(np.std(x, ddof=1)) if x.size > 1 else 0.0
                        row[s] = float(np.hypot(np.mean(x), sd))
                if row:
                    out[(c, p, zb)] = row
    return out


def study_budget(profiles, *, method="ipda", group=None, ax=None):
    """The error budget of a ``lidarsim dial`` study per line pair, as the CLI's
    ``budget.png``: for every budget row (random, temperature, humidity, surface pressure,
    frequency offset and jitter, line width, spectral impurity, class-mean virtual
    cross-sections, spectroscopy) the rms over the profiles [ppm] on a log axis, one line per
    row across the pairs, and the total (root sum of squares) as a thick black line. Rows
    more than five decades below the largest fall off the axis.

    The per-source numbers are not in ``summary.nc``, so this takes ``profiles.nc`` and
    computes them as ``budget.csv`` does (:func:`budget_table`).

    Parameters
    ----------
    profiles : xarray.Dataset
        ``profiles.nc`` of ``lidarsim dial`` (arrays on (profile, pair, retrieval); one
        ``<source>_ppm`` variable [ppm] per budget row).
    method : {"ipda", "dial"}
        ``ipda`` (default): the columns, one slot per pair. ``dial``: the cells of the first
        pair (or of ``group``'s), one slot per cell, labelled by altitude [km].
    group : str, optional
        Latitude class (``tropical``, ``mid``, ``high``) or ``all`` (default: every profile).
    ax : matplotlib.axes.Axes, optional
        Where to draw; default a new figure.

    Returns
    -------
    matplotlib.axes.Axes
    """
    table = budget_table(profiles, method=method)
    group = group or "all"
    rows = {k: v for k, v in table.items() if k[0] == group}
    if not rows:
        raise ValueError(
            f"study_budget: no class {group!r} (classes: {sorted({k[0] for k in table})})"
        )
    keys = list(rows)
    if method == "dial":
        first = keys[0][1]
        keys = sorted([k for k in keys if k[1] == first], key=lambda k: k[2])
        tick = [f"{k[2] / 1000:g}" for k in keys]
        xlabel = f"bottom of the DIAL cell [km] ({first})"
    else:
        tick, xlabel = _pair_names([k[1] for k in keys])
    sources = list(dict.fromkeys(s for k in keys for s in rows[k]))
    if ax is None:
        ax = _new_axes((max(8.0, 1.1 * len(keys) + 5.0), 5.5))
    colours = _cmap("tab10" if len(sources) <= 10 else "tab20")
    total = np.array([np.sqrt(sum(v**2 for v in rows[k].values())) for k in keys])
    top = float(np.nanmax(total)) * 2.0
    bottom = top / 2.0 * 1e-5
    xs = np.arange(len(keys), dtype=float)
    for j, s in enumerate(sources):
        y = np.array([rows[k].get(s, np.nan) for k in keys])
        y = np.where(y > 0, y, np.nan)
        if not np.isfinite(y).any():
            continue
        (ln,) = ax.plot(xs, y, marker="o", markersize=6, linewidth=1.2,
                        color=colours(j % colours.N), label=s.replace("_", " "))
        ln.lidarsim_role = "budget"
    (ln,) = ax.plot(xs, total, color="black", linewidth=3.0, marker="o", markersize=7,
                    label="total (root sum of squares)")
    ln.lidarsim_role = "total"
    ax.set_yscale("log")
    ax.set_ylim(bottom, top)
    ax.set_xticks(xs)
    ax.set_xticklabels(tick, rotation=30 if len(keys) > 4 else 0,
                       ha="right" if len(keys) > 4 else "center")
    ax.set_xlim(-0.5, len(keys) - 0.5)
    ax.grid(True, axis="y", which="major", alpha=0.3)
    unit = _fraction_unit(next(iter(
        profiles[s + "_ppm"].attrs.get("units", "1e-6") for s in sources)))
    gas = _gas(profiles["truth_ppm"].attrs.get("long_name", "")) if "truth_ppm" in profiles.variables else None
    _style_axes(
        ax,
        xlabel,
        f"error [{unit}] (rms over profiles; random: 1σ)",
        f"{'IPDA' if method == 'ipda' else 'DIAL'} X{gas or 'gas'} error budget"
        f" (class {group})",
    )
    _legend_outside(ax)
    return ax
