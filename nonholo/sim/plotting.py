"""Figures of a simulation result (matplotlib, headless-safe)."""
from __future__ import annotations

import sys

import matplotlib

if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nonholo.sim.scenario import Follower, Robot  # noqa: E402

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


def plot_result(result, path=None, robots=None, member: int = 0, max_robots: int = 8, snapshots: int = 6):
    """Four panels: path in the plane, errors, v and ω against time (formation snapshots
    and output errors when the scenario has followers or posture roots)."""
    if result.scenario.followers or any(r.posture for r in result.scenario.roots):
        return plot_formation(result, path, member, snapshots)
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


def _triangle(x, y, theta, size):
    """(3, 2) corners of a triangle pointing along the heading, centred on the axle midpoint."""
    c, s = np.cos(theta), np.sin(theta)
    body = np.array([[1.2, 0.0], [-0.6, 0.6], [-0.6, -0.6]]) * size
    return np.column_stack([x + c * body[:, 0] - s * body[:, 1], y + s * body[:, 0] + c * body[:, 1]])


def _robot_marker(ax, x, y, theta, color, size=0.6):  # noqa: D103
    """A robot's triangle (see ``_triangle``) drawn on ``ax``."""
    points = _triangle(x, y, theta, size)
    return ax.fill(points[:, 0], points[:, 1], color=color, alpha=0.8, lw=0)


def _links(formation):
    names = formation.names
    return [(names.index(p), i) for i, r in enumerate(formation.robots) if isinstance(r, Follower) for p in r.leaders]


def plot_formation(result, path=None, member: int = 0, snapshots: int = 6):
    formation = result.scenarios[member]
    t = result.t
    x, y, theta = (result.trajectory(f, member) for f in ("x", "y", "theta"))
    v, omega = result.trajectory("v", member), result.trajectory("omega", member)
    fig, axes = plt.subplots(2, 2, figsize=(12, 9), constrained_layout=True)
    ax_path, ax_err, ax_v, ax_w = axes.ravel()
    if result.reference_rows is not None:
        ax_path.plot(result.reference_rows[:, 1], result.reference_rows[:, 2], "k--", lw=1, label="reference")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, robot in enumerate(formation.robots):
        color = colors[i % len(colors)]
        role = robot.controller.name if isinstance(robot, Robot) else robot.law
        ax_path.plot(x[i], y[i], color=color, lw=1.1, label=f"{robot.name} ({role})")
        ax_v.plot(t, v[i], color=color, lw=1, label=robot.name)
        ax_w.plot(t, omega[i], color=color, lw=1, label=robot.name)
        if isinstance(robot, Robot) and robot.posture:
            ax_path.plot(*robot.goal[:2], "*", color=color, ms=14)
            distance = np.hypot(x[i] - robot.goal[0], y[i] - robot.goal[1])
            ax_err.semilogy(t, np.maximum(distance, 1e-16), color=color, lw=1.2, label=f"{robot.name}: distance to goal (m)")
        elif isinstance(robot, Follower):
            e1, e2 = result.output_errors(i, member)
            unit = "rad" if robot.outputs[1] == "phi" else "m"
            ax_err.semilogy(t, np.maximum(np.abs(e1), 1e-16), color=color, lw=1.2, label=f"{robot.name}: |{robot.outputs[0]} error| (m)")
            ax_err.semilogy(t, np.maximum(np.abs(e2), 1e-16), color=color, lw=1.2, ls="--",
                            label=f"{robot.name}: |{robot.outputs[1]} error| ({unit})")
    for k in np.linspace(0, t.size - 1, snapshots).astype(int):
        for i in range(len(formation.robots)):
            _robot_marker(ax_path, x[i, k], y[i, k], theta[i, k], colors[i % len(colors)])
        for parent, child in _links(formation):
            d = formation.robots[child].d
            px, py = x[child, k] + d * np.cos(theta[child, k]), y[child, k] + d * np.sin(theta[child, k])
            ax_path.plot([x[parent, k], px], [y[parent, k], py], color="0.4", lw=0.7)
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title="Paths (markers: snapshots; grey: leader axle → castor point)"
                if formation.followers else "Paths (markers: snapshots)")
    ax_path.set_aspect("equal", adjustable="datalim")   # the panel keeps its size (a straight path: not a strip)
    ax_err.set(xlabel="time (s)", ylabel="|error|", title="Formation output errors" if formation.followers else "Goal distance")
    ax_v.set(xlabel="time (s)", ylabel="v (m/s)", title="Driving speed demands")
    ax_w.set(xlabel="time (s)", ylabel=r"$\omega$ (rad/s)", title="Turn-rate demands")
    robust_limits(ax_v, [v], "m/s", "Driving speed demands")    # start-up spikes clipped, peak named
    robust_limits(ax_w, [omega], "rad/s", "Turn-rate demands")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    if ax_err.lines:
        ax_err.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, frameon=False)
    fig.legend(*ax_path.get_legend_handles_labels(), loc="outside lower center", ncol=min(4, len(formation.robots) + 1),
               fontsize=8, frameon=False)
    count = len(formation.robots)
    fig.suptitle(f"{formation.name}: {count} robot{'s' if count > 1 else ''}, {t[-1]:.5g} s, dt = {formation.dt:g} s")
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


def _write_gif(fig, ax, artists, draw, indices, path, fps, bar) -> None:
    """Render the frames by blitting on an Agg canvas and write them as one GIF with Pillow:
    the static part of the figure (axes, reference, labels) is drawn once and restored at
    each frame, and only ``artists`` (the moving ones) are drawn again; each frame is
    reduced to a 256-colour palette by Pillow's fast octree as it is taken. (Saving each
    frame as a whole figure drew every text and tick again: most of an animation's time.)"""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    canvas = FigureCanvasAgg(fig)
    artists = sorted(artists, key=lambda artist: artist.get_zorder())   # as the axes draw them
    for artist in artists:
        artist.set_animated(True)
    canvas.draw()   # the static part only: animated artists are left out
    background = canvas.copy_from_bbox(fig.bbox)
    frames = []
    for k in indices:
        canvas.restore_region(background)
        draw(k)
        for artist in artists:
            ax.draw_artist(artist)
        width, height = canvas.get_width_height(physical=True)
        frame = Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
        frames.append(frame.convert("RGB").quantize(256, method=Image.Quantize.FASTOCTREE))
        if bar is not None:
            bar.update(1)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)


def animate(result, path, member: int = 0, frames: int = 120, fps: int = 20, trail: float = 20.0,
            progress: bool = False, max_robots: int = 12):
    """Write an animation (GIF; MP4 when ``path`` ends in .mp4 and ffmpeg is installed):
    robots as labelled triangles with trails of ``trail`` seconds, formation links, the
    reference; ``progress`` shows a bar while frames are rendered."""
    from matplotlib.animation import FFMpegWriter, FuncAnimation

    formation = result.scenarios[member]
    t = result.t
    shown = list(range(min(max_robots, len(formation.robots))))
    x, y, theta = (result.trajectory(f, member)[shown] for f in ("x", "y", "theta"))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    span = max(np.ptp(x), np.ptp(y), 1.0)
    margin = 0.06 * span + 1.0
    width, height = np.ptp(x) + 2 * margin, np.ptp(y) + 2 * margin
    scale = 6.0 / max(width, height)
    fig, ax = plt.subplots(figsize=(max(3.0, width * scale) + 0.8, max(3.0, height * scale) + 0.6),
                           layout="constrained")
    ax.set(xlim=(x.min() - margin, x.max() + margin), ylim=(y.min() - margin, y.max() + margin), aspect="equal",
           xlabel="x (m)", ylabel="y (m)")
    ax.grid(True, alpha=0.3)
    if result.reference_rows is not None:
        ax.plot(result.reference_rows[:, 1], result.reference_rows[:, 2], "k--", lw=0.8)
    indices = np.linspace(0, t.size - 1, frames).astype(int)
    trail_steps = max(1, int(trail / formation.dt))
    links = [(p, c) for p, c in _links(formation) if p in shown and c in shown]
    size = 0.025 * span

    # The artists are made once and moved at each frame; the layout is computed once (a
    # constrained layout recomputed at every frame was most of an animation's time).
    trails, markers, labels = [], [], []
    for i in shown:
        color = colors[i % len(colors)]
        trails.append(ax.plot([], [], color=color, lw=1)[0])
        markers.append(_robot_marker(ax, x[i, 0], y[i, 0], theta[i, 0], color, size)[0])
        labels.append(ax.text(x[i, 0], y[i, 0], formation.robots[i].name, fontsize=7, color=color))
    link_lines = [ax.plot([], [], color="0.4", lw=0.7)[0] for _ in links]
    title = ax.set_title("", fontsize=9)

    def draw(k):
        start = max(0, k - trail_steps)
        for trail_line, marker, label, i in zip(trails, markers, labels, shown):
            trail_line.set_data(x[i, start:k + 1], y[i, start:k + 1])
            marker.set_xy(_triangle(x[i, k], y[i, k], theta[i, k], size))
            label.set_position((x[i, k] + 1.5 * size, y[i, k] + 1.5 * size))
        for line, (parent, child) in zip(link_lines, links):
            d = formation.robots[child].d
            line.set_data([x[parent, k], x[child, k] + d * np.cos(theta[child, k])],
                          [y[parent, k], y[child, k] + d * np.sin(theta[child, k])])
        title.set_text(f"{formation.name}: t = {t[k]:.1f} s")
        return []

    draw(indices[-1])
    fig.canvas.draw()
    fig.set_layout_engine("none")

    mp4 = str(path).lower().endswith(".mp4")
    if mp4 and not FFMpegWriter.isAvailable():
        raise ValueError("MP4 needs ffmpeg, which is not installed: write a .gif instead")
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(indices), unit="frame", desc=f"animating {path}", file=sys.stderr, leave=False)
    try:
        if mp4:
            animation = FuncAnimation(fig, lambda j: draw(indices[j]), frames=len(indices), blit=False)
            animation.save(path, writer=FFMpegWriter(fps=fps),
                           progress_callback=(lambda i, n: bar.update(1)) if bar else None)
        else:
            _write_gif(fig, ax, [*markers, *trails, *link_lines, *labels, title], draw, indices, path, fps, bar)
    finally:
        if bar is not None:
            bar.close()
        plt.close(fig)
    return path


def result_html(result) -> str:
    """A small HTML table of the roots' and followers' main figures and the figure (Jupyter)."""
    import base64
    import html
    import io

    summary = result.to_dict()
    rows = []
    for name, robot in list(summary["robots"].items())[:20]:
        if robot["role"] == "follower":
            f = robot["formation"]
            errors = "; ".join(f"{key[:-6]} {value['mean']:.3g}/{value['max']:.3g}/{value['final']:.3g}"
                               for key, value in f.items() if key.endswith("_error"))
            what = f"{robot['formation_law']} of {', '.join(f['leaders'])}"
        elif "posture" in robot:
            errors = f"goal distance final {robot['posture']['position_error']['final']:.3g} m"
            what = robot["controller"]
        else:
            e = robot["error"]
            errors = f"{e['mean']:.3g}/{e['max']:.3g}/{e['final']:.3g} m"
            what = robot["controller"]
        rows.append(f"<tr><td>{html.escape(name)}</td><td>{html.escape(what)}</td><td>{html.escape(errors)}</td>"
                    f"<td>{robot['control']['peak_v']:.3g}</td><td>{robot['control']['peak_omega']:.3g}</td></tr>")
    image = ""
    if result.record is not None:
        buffer = io.BytesIO()
        figure = result.plot()
        figure.savefig(buffer, format="png", dpi=60)
        plt.close(figure)
        image = f'<img src="data:image/png;base64,{base64.b64encode(buffer.getvalue()).decode()}"/>'
    return (f"<p>{html.escape(repr(result))}</p><table><tr><th>robot</th><th>law</th>"
            "<th>error mean/max/final</th><th>peak v (m/s)</th><th>peak ω (rad/s)</th></tr>"
            + "".join(rows) + "</table>" + image)
