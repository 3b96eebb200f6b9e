"""Figures of the studies (matplotlib, headless)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

MAX_PLOT_POINTS = 2500
ERROR_FLOOR = 1e-7  # m: the lower limit of logarithmic error axes
DPI = 100


def _stride(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_PLOT_POINTS))


def _save(fig, path):
    if path is not None:
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
    return fig


def plot_test(run, title: str, labels: dict, path=None, window: float | None = None):
    """One thesis test: desired and actual paths, error norm against time (log scale),
    v_d and ω_d. ``labels`` maps robot names to legend labels; ``window`` limits the path,
    v_d and ω_d panels to the first seconds (long, thin or fast-varying references)."""
    fig, axes = plt.subplots(2, 2, figsize=(13, 9))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.06, top=0.92, wspace=0.2, hspace=0.28)
    ax_path, ax_err, ax_v, ax_w = axes.ravel()
    t = run.t
    every = _stride(t.size)
    stop = int(np.searchsorted(t, window)) + 1 if window else t.size
    near = slice(0, stop, max(1, stop // MAX_PLOT_POINTS))
    ax_path.plot(run.x_d[near], run.y_d[near], "k--", lw=2.2, label="desired", zorder=5)
    error = np.maximum(run.error_norm(), ERROR_FLOOR)
    for i, name in enumerate(run.names):
        line, = ax_path.plot(run.x[i][near], run.y[i][near], lw=1.3)
        ax_err.plot(t[every], error[i][every], lw=1.3, color=line.get_color(), label=labels.get(name, name))
    ax_path.plot(run.x[0, 0], run.y[0, 0], "ko", ms=6, label="robots' start", zorder=6)
    shown = f", first {window:g} s" if window else ""
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title=f"Desired and actual paths{shown} (colours as on the right)")
    if not window:
        ax_path.set_aspect("equal", adjustable="datalim")
    ax_err.set(xlabel="time t (s)", ylabel="error norm ‖p_d − p‖ (m, log scale)", yscale="log",
               title="Position error norm", ylim=(ERROR_FLOOR, None))
    ax_v.plot(t[near], run.v_d[near], "k", lw=1.5)
    ax_v.set(xlabel="time t (s)", ylabel="v_d (m/s)", title=f"Desired driving speed v_d{shown}")
    ax_w.plot(t[near], run.omega_d[near], "k", lw=1.5)
    ax_w.set(xlabel="time t (s)", ylabel="ω_d (rad/s)", title=f"Desired turn rate ω_d{shown}")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    ax_path.legend(fontsize=9, loc="upper left")
    ax_err.legend(fontsize=9, loc="best")
    fig.suptitle(title, fontsize=14)
    return _save(fig, path)


def plot_comparison(tests, controllers, labels, series: dict, path=None):
    """Grouped bars per test (log scale): one bar per series (e.g. ours on the uniform
    grid, ours over solver steps, thesis) for every controller. ``series[name][test][controller]``
    is a mean error or None (no bar)."""
    fig, axes = plt.subplots(1, len(tests), figsize=(4.2 * len(tests), 4.8), sharey=True)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.24, top=0.88, wspace=0.08)
    width = 0.8 / len(series)
    x = np.arange(len(controllers))
    for ax, test in zip(np.atleast_1d(axes), tests):
        for j, (name, values) in enumerate(series.items()):
            heights = [values[test].get(c) for c in controllers]
            ax.bar(x[[h is not None for h in heights]] + (j - (len(series) - 1) / 2) * width,
                   [h for h in heights if h is not None], width, label=name)
        ax.set(yscale="log", title=test, xticks=x)
        ax.set_xticklabels([labels[c] for c in controllers], rotation=40, ha="right", fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("mean error norm (m, log scale)")
    np.atleast_1d(axes)[0].legend(fontsize=9)
    fig.suptitle("Mean position error: ours vs thesis Tables 5.2–5.5", fontsize=13)
    return _save(fig, path)


def plot_sweep(sweep, path=None, ax=None, default: float | None = None, claim: str | None = None):
    """A one-gain sweep as a line of the metric, a two-gain sweep as a heat map."""
    own_figure = ax is None
    if own_figure:
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        fig.subplots_adjust(left=0.14, right=0.97, bottom=0.12, top=0.86)
    else:
        fig = ax.figure
    label = f"{sweep.metric} error norm (m)"
    if len(sweep.axes) == 1:
        axis = sweep.axes[0]
        ax.plot(axis.values, sweep.values, "o-", ms=3, lw=1.5)
        if default is not None:
            ax.axvline(default, color="gray", ls=":", lw=1.2, label=f"Table 5.1: {default:g}")
            ax.legend(fontsize=8)
        positive = sweep.values[sweep.values > 0]
        if positive.size and positive.max() / positive.min() > 100:
            ax.set_yscale("log")
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
        return _save(fig, path)
    return fig


def plot_sweep_panels(effects, title: str, path=None):
    """Several one-gain sweeps of one controller side by side (Figures 5.25–5.38)."""
    fig, axes = plt.subplots(1, len(effects), figsize=(4.6 * len(effects), 4.6), squeeze=False)
    fig.subplots_adjust(left=0.28 / len(effects), right=0.99, bottom=0.13, top=0.76, wspace=0.32)
    for ax, effect in zip(axes[0], effects):
        plot_sweep(effect.sweep, ax=ax, default=effect.default, claim=effect.claim)
    fig.suptitle(title, fontsize=13)
    return _save(fig, path)
