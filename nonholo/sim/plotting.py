"""Figures of a simulation result (matplotlib, headless-safe)."""
from __future__ import annotations

import matplotlib

if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Start-up transients can be 100× the steady commands; the v and ω panels show the
# central 99 % of the samples and state the clipped peak in their title.
ROBUST_PERCENTILES = (0.5, 99.5)


def robust_limits(ax, series, unit: str, title: str) -> None:
    """Y-limits from the central percentiles of ``series``; the title names a clipped peak."""
    values = np.concatenate([np.ravel(s) for s in series])
    low, high = np.percentile(values, ROBUST_PERCENTILES)
    span = max(high - low, 1e-9)
    low, high = low - 0.1 * span, high + 0.1 * span
    peak = values[np.argmax(np.abs(values))]
    if peak > high or peak < low:
        ax.set_ylim(low, high)
        title += f" (peak {peak:.3g} {unit} clipped)"
    ax.set_title(title)


def plot_result(result, robots=None, path=None, max_robots: int = 8):
    """Four panels: path in the plane, error norm, v and ω against time."""
    indices = [result.index(r) for r in robots] if robots is not None else list(range(min(max_robots, len(result.names))))
    fig, axes = plt.subplots(2, 2, figsize=(12, 9), constrained_layout=True)
    ax_path, ax_err, ax_v, ax_w = axes.ravel()
    t = result.t
    ax_path.plot(result.x_d, result.y_d, "k--", lw=1.5, label="desired")
    ax_v.plot(t, result.v_d, "k--", lw=1.2)
    ax_w.plot(t, result.omega_d, "k--", lw=1.2)
    error = result.error_norm()
    for i in indices:
        robot = result.scenario.robots[i]
        label = robot.name if robot.name == robot.controller.name else f"{robot.name} ({robot.controller.name})"
        line, = ax_path.plot(result.x[i], result.y[i], lw=1.2, label=label)
        color = line.get_color()
        ax_path.plot(result.x[i, 0], result.y[i, 0], "o", color=color, ms=5)
        ax_err.plot(t, error[i], lw=1.2, color=color)
        ax_v.plot(t, result.v[i], lw=1.0, color=color)
        ax_w.plot(t, result.omega[i], lw=1.0, color=color)
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title="Path (dots: starts)", aspect="equal")
    ax_err.set(xlabel="time (s)", ylabel="error norm (m)", title=r"Position error $\|p_d - p\|$")
    shown = error[indices]
    if shown.max() > 0 and shown.max() / max(shown[:, -1].max(), 1e-12) > 1e3:
        ax_err.set_yscale("log")
    ax_v.set(xlabel="time (s)", ylabel="v (m/s)")
    ax_w.set(xlabel="time (s)", ylabel=r"$\omega$ (rad/s)")
    robust_limits(ax_v, [result.v[indices], result.v_d], "m/s", "Driving speed (dashed: $v_d$)")
    robust_limits(ax_w, [result.omega[indices], result.omega_d], "rad/s", r"Turn rate (dashed: $\omega_d$)")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    fig.legend(*ax_path.get_legend_handles_labels(), loc="outside lower center", ncol=min(4, len(indices) + 1),
               fontsize=9, frameon=False)
    fig.suptitle(f"{result.scenario.name}: {result.scenario.reference.kind} reference, "
                 f"{result.t[-1]:.5g} s, dt = {result.scenario.dt:.4g} s")
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
