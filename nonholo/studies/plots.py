"""Figures of the studies (matplotlib, headless).

Rules every study figure follows:

* **No line hidden.** Overlaid series get distinct colours *and* dash patterns, the widest
  drawn first (``series_style``): where two lines coincide the thin one shows inside the
  wide one. Where overlays would still hide each other (a controller's v, ω, heading error),
  each series gets its own panel (small multiples).
* **No legend over data.** Legends sit outside the axes (``legend_below``).
* **Start-up spikes are clipped, and the figure says so.** Y-limits come from the central
  99.5 % of the samples (``clip_spikes``); a clipped peak is named in the panel's title.
"""
from __future__ import annotations

import math
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.ticker import LogFormatterSciNotation  # noqa: E402

MAX_PLOT_POINTS = 2500
ERROR_FLOOR = 1e-7  # m: the lower limit of logarithmic error axes
DPI = 100
PNG_COMPRESSION = 1
ROBUST_PERCENTILES = (0.25, 99.75)
# Matplotlib settings of the report's figures (``ReportWriter.add`` applies them). Titles sit
# at the top of their axes: none of our axes has decorations above it, which is all that
# matplotlib's automatic title placement looks for, at the cost of a tight bounding box of
# every axis at every draw (a third of the report's drawing time).
FIGURE_STYLE = {"axes.titley": 1.0}

# Distinct colour, dash pattern and width per series; drawn widest first.
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
_DASHES = ("-", (0, (6, 2)), (0, (1, 1.2)), (0, (5, 2, 1, 2)), (0, (2, 1)), "-", (0, (4, 1, 1, 1, 1, 1)), (0, (8, 3)))
_WIDTHS = (3.2, 2.4, 2.2, 1.7, 1.4, 1.0, 1.6, 1.2)


def series_style(i: int) -> dict:
    """Matplotlib keywords for the i-th overlaid series (see the module docstring)."""
    k = i % len(_COLORS)
    return {"color": _COLORS[k], "ls": _DASHES[k], "lw": _WIDTHS[k], "zorder": 2 + i}


def _stride(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_PLOT_POINTS))


def _thin(t: np.ndarray, *arrays: np.ndarray, window: float | None = None):
    """Samples up to ``window`` seconds (all if None), thinned to about MAX_PLOT_POINTS
    blocks, each drawn at its largest-magnitude sample (so that spikes are not lost)."""
    stop = int(np.searchsorted(t, window, side="right")) if window else t.size
    step = max(1, stop // MAX_PLOT_POINTS)
    if step == 1:
        return (t[:stop], *(np.asarray(a)[..., :stop] for a in arrays))
    blocks = stop // step
    out = [t[:blocks * step:step]]
    for a in arrays:
        a = np.asarray(a)[..., :blocks * step].reshape(*np.shape(a)[:-1], blocks, step)
        out.append(np.take_along_axis(a, np.abs(a).argmax(axis=-1)[..., None], axis=-1)[..., 0])
    return tuple(out)


_SUPERSCRIPT = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
_POWER = re.compile(r"^\$\\mathdefault\{(-?)(?:([\d.]+)\\times\s*)?(\d+)\^\{(-?\d+)\}\}\$$")


class PlainLogFormatter(LogFormatterSciNotation):
    """Matplotlib's log-axis labels (10⁻⁴, 2×10⁻⁴, …) written in plain text with superscript
    digits instead of mathtext: the same labels, without a TeX-like parse of each (0.4 s of
    the report's figures). A label of any other form is left to mathtext."""

    def __call__(self, x, pos=None):
        label = super().__call__(x, pos)
        match = _POWER.match(label)
        if not match:
            return label
        sign, coefficient, base, exponent = match.groups()
        return f"{sign}{coefficient + '×' if coefficient else ''}{base}{exponent.translate(_SUPERSCRIPT)}"


def plain_log_labels(fig) -> None:
    """Make every log-axis formatter of ``fig`` that is matplotlib's default a
    ``PlainLogFormatter``: the formatter keeps its state (ticks, which minor ticks are
    labelled), only its labels' writing changes."""
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for formatter in (axis.get_major_formatter(), axis.get_minor_formatter()):
                if type(formatter) is LogFormatterSciNotation:
                    formatter.__class__ = PlainLogFormatter


def save_figure(fig, path, dpi: int = DPI):
    """Write ``fig`` as a PNG to ``path`` and close it (nothing if ``path`` is None); returns
    ``fig``. Log axes get plain-text labels (``plain_log_labels``). zlib level
    ``PNG_COMPRESSION``: half the encoding time of the default level 6 for files about a
    sixth larger (the report's figures are flat colours and lines)."""
    plain_log_labels(fig)
    if path is not None:
        png = str(path).lower().endswith(".png")   # (SVG, PDF: matplotlib's own writers, no zlib level)
        try:
            fig.savefig(path, dpi=dpi, **({"pil_kwargs": {"compress_level": PNG_COMPRESSION}} if png else {}))
        finally:
            plt.close(fig)
    return fig


def robust_range(series, include=()) -> tuple[float, float]:
    """The central percentiles of ``series`` (and every value of ``include``), padded."""
    values = np.concatenate([np.ravel(s) for s in series])
    values = values[np.isfinite(values)]
    if values.size == 0:
        return -1.0, 1.0
    low, high = np.percentile(values, ROBUST_PERCENTILES)
    for extra in include:
        low, high = min(low, float(np.min(extra))), max(high, float(np.max(extra)))
    span = max(high - low, 0.05 * max(abs(low), abs(high)), 1e-3)
    return float(low - 0.12 * span), float(high + 0.12 * span)


def peak_note(t: np.ndarray, values: np.ndarray, low: float, high: float, unit: str) -> str:
    """"start-up peak 340 rad/s at t = 0.01 s clipped" if ``values`` leave [low, high]."""
    values = np.asarray(values)
    k = int(np.nanargmax(np.abs(values)))
    peak = float(values[k])
    if low <= peak <= high:
        return ""
    start_up = t[k] <= 0.1 * t[-1]
    space = "" if unit == "°" else " "
    return f"{'start-up ' if start_up else ''}peak {peak:.3g}{space}{unit} at t = {t[k]:.2g} s, clipped"


def clip_spikes(ax, t: np.ndarray, series, unit: str, include=()) -> str:
    """Y-limits of ``ax`` from the central percentiles of ``series`` (1-D arrays on ``t``)
    and the values in ``include`` (e.g. the reference), if a peak leaves them; returns the
    notes naming the clipped peaks ("" if none)."""
    low, high = robust_range(series, include)
    notes = [note for note in (peak_note(t, s, low, high, unit) for s in series) if note]
    if notes:
        ax.set_ylim(low, high)
    return "; ".join(notes)


def legend_below(fig, ax_or_axes, ncol: int, fontsize: float = 9, y: float = 0.0, **kwargs):
    """One legend for the figure, under the axes (outside every plot)."""
    axes = np.atleast_1d(ax_or_axes).ravel()
    handles, labels = {}, []
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            if label not in handles and not label.startswith("_"):
                handles[label] = handle
                labels.append(label)
    return fig.legend([handles[label] for label in labels], labels, loc="lower center", ncol=ncol,
                      fontsize=fontsize, bbox_to_anchor=(0.5, y), frameon=False, **kwargs)


def wrap_degrees(angle: np.ndarray) -> np.ndarray:
    """An angle in radians as degrees wrapped to (−180°, 180°]."""
    return -np.degrees(np.angle(np.exp(-1j * angle)))


# ------------------------------------------------------------------ the leader tests

def plot_test(run, title: str, labels: dict, path=None, window: float | None = None):
    """One thesis test, overview: desired and actual paths, and the error norm against time
    (log scale), every controller in its own style (``series_style``)."""
    fig, (ax_path, ax_err) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw={"width_ratios": (1, 1.25)})
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.2, top=0.88, wspace=0.18)
    t = run.t
    near_t, x_d, y_d = _thin(t, run.x_d, run.y_d, window=window)
    ax_path.plot(x_d, y_d, color="0.55", lw=6, solid_capstyle="round", label="desired path", zorder=1)
    error = np.maximum(run.error_norm(), ERROR_FLOOR)
    every = _stride(t.size)
    for i, name in enumerate(run.names):
        style = series_style(i)
        _, x, y = _thin(t, run.x[i], run.y[i], window=window)
        ax_path.plot(x, y, **style, label=labels.get(name, name))
        ax_err.plot(t[every], error[i][every], **style)
    ax_path.plot(run.x[0, 0], run.y[0, 0], "ko", ms=6, label="robots' start", zorder=20)
    shown = f", first {window:g} s" if window else ""
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title=f"Desired and actual paths{shown}")
    if not window:
        ax_path.set_aspect("equal", adjustable="datalim")
    ax_err.set(xlabel="time t (s)", ylabel="‖p_d − p‖ (m, log scale)", yscale="log", ylim=(ERROR_FLOOR, None),
               title=f"Position error norm (values below {ERROR_FLOOR:g} m drawn at {ERROR_FLOOR:g} m)")
    for ax in (ax_path, ax_err):
        ax.grid(True, alpha=0.3)
    legend_below(fig, ax_path, ncol=len(run.names) + 2)
    fig.suptitle(title, fontsize=14)
    return save_figure(fig, path)


def plot_test_inputs(run, title: str, labels: dict, path=None, window: float | None = None):
    """Small multiples, one row per controller: the applied driving speed v and turn rate ω
    beside v_d and ω_d, and the heading error e3 = θ_d − θ (wrapped). Columns share their
    y-axis; start-up spikes are clipped and named in the panel's title."""
    n = len(run.names)
    height = 2.1 * n + 1.2
    fig, axes = plt.subplots(n, 3, figsize=(12.5, height), sharex=True, sharey="col", squeeze=False)
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.55 / height, top=1 - 0.95 / height, wspace=0.2, hspace=0.75)
    t = run.t
    heading = wrap_degrees(run.theta_d[None, :] - run.theta)
    tt, v, omega, e3, v_d, omega_d = _thin(t, run.v, run.omega, heading, run.v_d, run.omega_d, window=window)
    stop = int(np.searchsorted(t, window, side="right")) if window else t.size
    full = (run.v[:, :stop], run.omega[:, :stop], heading[:, :stop])  # the notes name exact peaks and times
    columns = ((v, v_d, "v (m/s)", "m/s", "applied v", "desired v_d"),
               (omega, omega_d, "ω (rad/s)", "rad/s", "applied ω", "desired ω_d"),
               (e3, np.zeros_like(tt), "e3 (°)", "°", "heading error e3", "zero heading error"))
    for c, (values, reference, ylabel, unit, kind, reference_label) in enumerate(columns):
        low, high = robust_range(list(values), include=[reference])
        for i, name in enumerate(run.names):
            ax = axes[i, c]
            ax.plot(tt, reference, color="k", lw=0.9, ls=(0, (4, 2)), zorder=3, label=reference_label)
            ax.plot(tt, values[i], color=series_style(i)["color"], lw=1.4, zorder=2, label="_applied")
            ax.grid(True, alpha=0.3)
            note = peak_note(t[:stop], full[c][i], low, high, unit)
            ax.set_title(f"{labels.get(name, name)}: {kind}" + (f"\n{note}" if note else ""), fontsize=9,
                         color="#a31515" if note else "black")
            ax.set_ylabel(ylabel, fontsize=9)
        axes[0, c].set_ylim(low, high)  # shared by the column
        axes[-1, c].set_xlabel("time t (s)")
    shown = f", first {window:g} s" if window else ""
    fig.suptitle(f"{title}: what each controller applies{shown} (dashed: v_d, ω_d and e3 = 0)", fontsize=13)
    return save_figure(fig, path)


def plot_comparison(tests, controllers, labels, series: dict, path=None):
    """Grouped bars per test (log scale): one bar per series (e.g. ours on the uniform
    grid, ours over solver steps, thesis) for every controller. ``series[name][test][controller]``
    is a mean error or None (no bar)."""
    fig, axes = plt.subplots(1, len(tests), figsize=(4.2 * len(tests), 5.0), sharey=True)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.3, top=0.88, wspace=0.08)
    width = 0.8 / len(series)
    x = np.arange(len(controllers))
    hatches = ("", "//", "..", "xx")
    for ax, test in zip(np.atleast_1d(axes), tests):
        for j, (name, values) in enumerate(series.items()):
            heights = [values[test].get(c) for c in controllers]
            ax.bar(x[[h is not None for h in heights]] + (j - (len(series) - 1) / 2) * width,
                   [h for h in heights if h is not None], width, label=name, color=_COLORS[j],
                   hatch=hatches[j % len(hatches)], edgecolor="white", lw=0)
        ax.set(yscale="log", title=test, xticks=x)
        ax.set_xticklabels([labels[c] for c in controllers], rotation=40, ha="right", fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("mean error norm (m, log scale)")
    legend_below(fig, np.atleast_1d(axes)[0], ncol=len(series), fontsize=10)
    fig.suptitle("Mean position error: ours vs thesis Tables 5.2–5.5", fontsize=13)
    return save_figure(fig, path)


# ------------------------------------------------------------------ sweeps

def plot_sweep(sweep, path=None, ax=None, default: float | None = None, claim: str | None = None):
    """A one-gain sweep as a line of the metric, a two-gain sweep as a heat map; the
    default gain (``default``) is a labelled dotted line (no legend)."""
    own_figure = ax is None
    if own_figure:
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        fig.subplots_adjust(left=0.14, right=0.97, bottom=0.12, top=0.86)
    else:
        fig = ax.figure
    label = f"{sweep.metric} error norm (m)" if sweep.output == "position" else \
        f"{sweep.metric} |{sweep.output} error| ({sweep.unit})"
    if len(sweep.axes) == 1:
        axis = sweep.axes[0]
        ax.plot(axis.values, sweep.values, "o-", ms=3, lw=1.5)
        positive = sweep.values[sweep.values > 0]
        if positive.size and positive.max() / positive.min() > 100:
            ax.set_yscale("log")
        if default is not None:
            ax.axvline(default, color="gray", ls=":", lw=1.4)
            ax.annotate(f"Table 5.1: {default:g}", (default, 1.0), xycoords=("data", "axes fraction"),
                        xytext=(3, -3), textcoords="offset points", ha="left", va="top", fontsize=8, color="0.35")
        title = f"{sweep.controller}: {axis.name} → {sweep.trend().word}"
        if claim:
            title += f"\n(thesis: {claim})"
        ax.set(xlabel=f"{axis.name}", ylabel=label, title=title)
        ax.grid(True, alpha=0.3)
    else:
        first, second = sweep.axes
        values = sweep.values
        positive = values[values > 0]
        norm = LogNorm(positive.min(), positive.max()) if positive.size and positive.max() / positive.min() > 100 \
            else None
        mesh = ax.pcolormesh(second.values, first.values, values, shading="nearest", norm=norm, cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set(xlabel=second.name, ylabel=first.name,
               title=f"{sweep.scenario}, {sweep.robot} ({sweep.controller}): {sweep.metric} error")
    if own_figure:
        return save_figure(fig, path)
    return fig


def plot_sweep_panels(effects, title: str, path=None):
    """Several one-gain sweeps of one controller side by side (Figures 5.25–5.38)."""
    fig, axes = plt.subplots(1, len(effects), figsize=(4.6 * len(effects), 4.6), squeeze=False)
    fig.subplots_adjust(left=0.28 / len(effects), right=0.99, bottom=0.13, top=0.76, wspace=0.32)
    for ax, effect in zip(axes[0], effects):
        plot_sweep(effect.sweep, ax=ax, default=effect.default, claim=effect.claim)
    fig.suptitle(title, fontsize=13)
    return save_figure(fig, path)


# ------------------------------------------------------------------ formations

def _robot_marker(ax, x, y, theta, color, size=0.55):
    """A triangle pointing along the heading, centred on the axle midpoint."""
    c, s = math.cos(theta), math.sin(theta)
    body = np.array([[1.2, 0.0], [-0.6, 0.6], [-0.6, -0.6]]) * size
    ax.fill(x + c * body[:, 0] - s * body[:, 1], y + s * body[:, 0] + c * body[:, 1], color=color, alpha=0.85,
            lw=0, zorder=10)


def plot_formation_case(run, title: str, path=None, snapshots: int = 6, errors=None):
    """A formation run: paths with snapshots (triangles at equal time steps; grey: leader
    axle → follower castor point), the follower output errors (log scale), and each robot's
    applied v and ω (one panel per robot and input; start-up spikes clipped and named).

    ``errors``: (label, array, line style) series for the error panel; default: every
    follower's two output errors in the follower's colour (solid: first output, dashed:
    second)."""
    formation = run.formation
    names = list(formation.names)
    n = len(names)
    t = run.t
    x, y, theta, v, omega = (run.trajectory(f) for f in ("x", "y", "theta", "v", "omega"))
    fig = plt.figure(figsize=(13, 11))
    outer = fig.add_gridspec(2, 1, height_ratios=(1.45, 1.6), left=0.06, right=0.99, bottom=0.055, top=0.91,
                             hspace=0.38)
    top = outer[0].subgridspec(1, 2, width_ratios=(1, 1.15), wspace=0.18)
    grid = outer[1].subgridspec(2, n, hspace=0.6, wspace=0.22)
    ax_path = fig.add_subplot(top[0])
    ax_err = fig.add_subplot(top[1])
    if run.reference_rows is not None:
        ax_path.plot(run.reference_rows[:, 1], run.reference_rows[:, 2], color="0.6", lw=3, zorder=1,
                     label="leader's reference")
    for i, name in enumerate(names):
        ax_path.plot(x[i], y[i], color=_COLORS[i % len(_COLORS)], lw=1.3, zorder=3, label=name)
    for k in np.linspace(0, t.size - 1, snapshots).astype(int):
        for i in range(n):
            _robot_marker(ax_path, x[i, k], y[i, k], theta[i, k], _COLORS[i % len(_COLORS)])
        for follower in formation.followers:
            j = names.index(follower.name)
            px, py = x[j, k] + follower.d * math.cos(theta[j, k]), y[j, k] + follower.d * math.sin(theta[j, k])
            for parent in follower.leaders:
                p = names.index(parent)
                ax_path.plot([x[p, k], px], [y[p, k], py], color="0.35", lw=0.8, zorder=9)
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title="Paths (triangles: snapshots at equal time steps)")
    ax_path.set_aspect("equal", adjustable="datalim")
    if errors is None:
        errors = []
        symbols = {"l": "l", "phi": "φ", "l1": "l1", "l2": "l2"}
        units = {"l": "m", "phi": "rad", "l1": "m", "l2": "m"}
        for follower in formation.followers:
            color = _COLORS[names.index(follower.name) % len(_COLORS)]
            for k, (output, e) in enumerate(zip(follower.outputs, run.output_errors(follower.name))):
                errors.append((f"{follower.name}: |{symbols[output]} − {symbols[output]}_d| ({units[output]})",
                               np.abs(e), {"color": color, "ls": ("-", (0, (5, 2)))[k], "lw": (2.6, 1.4)[k],
                                           "zorder": 2 + k}))
    every = _stride(t.size)
    for label, values, style in errors:
        ax_err.semilogy(t[every], np.maximum(values[every], 1e-16), **style, label=label)
    ax_err.set(xlabel="time t (s)", ylabel="|output error| (log scale)", title="Follower output errors",
               ylim=(1e-16, None))
    for ax in (ax_path, ax_err):
        ax.grid(True, alpha=0.3)
    ax_path.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.16), ncol=min(4, n + 1), frameon=False)
    ax_err.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.16), ncol=2, frameon=False)
    tt, vv, ww = _thin(t, v, omega)
    for row, (values, label, unit) in enumerate(((vv, "applied v (m/s)", "m/s"), (ww, "applied ω (rad/s)", "rad/s"))):
        low, high = robust_range(list(values))
        shared = None
        for i, name in enumerate(names):
            ax = fig.add_subplot(grid[row, i], sharey=shared)
            shared = shared or ax
            ax.plot(tt, values[i], color=_COLORS[i % len(_COLORS)], lw=1.1)
            note = peak_note(t, (v, omega)[row][i], low, high, unit)
            ax.set_title(f"{name}: {label}" + (f"\n{note}" if note else ""), fontsize=8.5,
                         color="#a31515" if note else "black")
            ax.grid(True, alpha=0.3)
            if row == 1:
                ax.set_xlabel("time t (s)")
        shared.set_ylim(low, high)
    fig.suptitle(title, fontsize=13)
    return save_figure(fig, path)
