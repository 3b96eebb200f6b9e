"""Figures of a simulation result (matplotlib, headless-safe)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg") if matplotlib.get_backend().lower() in ("agg", "") else None  # noqa: E702
import matplotlib.pyplot as plt  # noqa: E402


def plot_result(result, robots=None, path=None, max_robots: int = 8):
    """Four panels: path in the plane, error norm, v and ω against time."""
    indices = [result.index(r) for r in robots] if robots is not None else list(range(min(max_robots, len(result.names))))
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5), constrained_layout=True)
    ax_path, ax_err, ax_v, ax_w = axes.ravel()
    t = result.t
    ax_path.plot(result.x_d, result.y_d, "k--", lw=1.5, label="desired")
    ax_v.plot(t, result.v_d, "k--", lw=1.2, label="$v_d$")
    ax_w.plot(t, result.omega_d, "k--", lw=1.2, label=r"$\omega_d$")
    error = result.error_norm()
    for i in indices:
        robot = result.scenario.robots[i]
        label = f"{robot.name} ({robot.controller.name})"
        line, = ax_path.plot(result.x[i], result.y[i], lw=1.2, label=label)
        ax_path.plot(result.x[i, 0], result.y[i, 0], "o", color=line.get_color(), ms=5)
        ax_err.plot(t, error[i], lw=1.2, color=line.get_color(), label=label)
        ax_v.plot(t, result.v[i], lw=1.0, color=line.get_color(), label=robot.name)
        ax_w.plot(t, result.omega[i], lw=1.0, color=line.get_color(), label=robot.name)
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title="Path (circle: start)", aspect="equal")
    ax_err.set(xlabel="time (s)", ylabel="error norm (m)", title=r"Position error $\|p_d - p\|$")
    if error[indices].max() > 0 and error[indices].max() / max(error[indices][:, -1].max(), 1e-12) > 1e3:
        ax_err.set_yscale("log")
    ax_v.set(xlabel="time (s)", ylabel="v (m/s)", title="Driving speed")
    ax_w.set(xlabel="time (s)", ylabel=r"$\omega$ (rad/s)", title="Turn rate")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(f"{result.scenario.name}: {result.scenario.reference.kind} reference, "
                 f"{result.t[-1]:.5g} s, dt = {result.scenario.dt:g} s")
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
