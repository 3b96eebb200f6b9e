"""Measure what raising each gain of each controller does, for the pages in this folder.

    python3 docs/controllers/measure.py            # print the tables (markdown)
    python3 docs/controllers/measure.py --write    # also update the pages and their figures
    python3 docs/controllers/measure.py --only polar kanayama index

Every gain is swept over five values around its default (×0.25, ×0.5, ×1, ×2, ×4 unless a
page says otherwise), the other gains at their defaults, in the set-up of the thesis study
that uses the law:

* tracking laws: Test 1 (figure eight), the robot at the origin with heading 0, N = 100 000
  steps: the bundled example ``test1-eight`` (the same batch as ``nonholo sweep test1-eight
  --robot LAW --gain NAME=…``, which reports the error columns);
* followers: the formation study's ``lphi-T1`` (l–φ follower 4 m behind a dynamic-feedback
  leader on Test 1) and ``ll-T1`` (the l–l follower F of Eq 5.10) cases;
* posture laws: from (−10, −10), heading 0, to the goal (0, 0), 60 s, dt = 0.01 s.

With ``--write`` the table between ``<!-- measured:begin -->`` and ``<!-- measured:end -->``
of each page is replaced, and ``LAW.png`` (two panels against the gain, relative to its
default) is redrawn. Takes a few minutes with warm compiled-code caches.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))  # run from a checkout without installing

import nonholo as nh  # noqa: E402
from nonholo import examples  # noqa: E402
from nonholo.studies.sweep import GainAxis, sweep_robots  # noqa: E402

FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)
TRACKING = {
    "approximate-linearization": {"zeta": (0.1, 0.3, 0.5, 0.7, 0.9), "b": None},
    "nonlinear": {"zeta": (0.1, 0.3, 0.5, 0.7, 0.9), "b": None},
    "cascaded": {"c1": None, "c2": None, "c3": (-0.9, -0.6, -0.414, 0.0, 1.0)},
    "kanayama": {"kx": None, "ky": None, "ktheta": None},
    "offset-point": {"d": None, "k1": None, "k2": None},
    "dynamic-feedback": {"kp": None, "kd": None},
}
FOLLOWERS = {"separation-bearing": ("lphi-T1", ("k1", "k2", "d")),
             "separation-separation": ("ll-T1", ("k1", "k2", "d"))}
POSTURE = {"time-varying": ("k1", "k2", "k3", "k5", "k6"), "polar": ("k1", "k2", "k3"),
           "dynamic-feedback-posture": ("kp1", "kd1", "kp2", "kd2")}
NEAR = 0.1  # m: "within reach" of the goal


def grid(default: float, values) -> tuple[float, ...]:
    return tuple(values) if values is not None else tuple(round(default * f, 10) for f in FACTORS)


def relative(gain: str, value: float, default: float) -> float:
    """The x of the figures: value/default (for c3 of the cascaded law, (1 + c3)/(1 + c3_default):
    1 + c3 is what scales the cross-track correction)."""
    return (1 + value) / (1 + default) if gain == "c3" else value / default


# ------------------------------------------------------------------ tracking laws

def measure_tracking(law: str) -> dict:
    scenario = nh.load_scenario(examples.path("test1-eight"))
    base = next(r for r in scenario.robots if r.controller.name == law)
    defaults = dict(base.controller.gains)
    rows = []
    for gain, values in TRACKING[law].items():
        default = defaults.get(gain, defaults.get(f"{gain}1"))
        values = grid(default, values)
        robots = sweep_robots(base, [GainAxis(gain, np.array(values, dtype=float))])
        metrics = nh.simulate(dataclasses.replace(scenario, robots=tuple(robots)), record=False).metrics
        for i, value in enumerate(values):
            rows.append({"gain": gain, "value": value, "default": default, "x": relative(gain, value, default),
                         "mean error (m)": metrics.error_mean[i], "e(T) (m)": metrics.error_final[i],
                         "mean |e3| (rad)": metrics.heading_mean[i], "peak |v| (m/s)": metrics.peak_v[i],
                         "peak |ω| (rad/s)": metrics.peak_omega[i]})
    return {"rows": rows, "panels": ("mean error (m)", "peak |ω| (rad/s)"),
            "setup": "Test 1 (figure eight, T = 80π s, N = 100 000), robot at the origin with heading 0"}


# ------------------------------------------------------------------ followers

def measure_follower(law: str) -> dict:
    from nonholo.formation import simulate_formation
    from nonholo.studies.formation import build_cases

    case, gains = FOLLOWERS[law]
    formation = build_cases()[case]
    index = max(i for i, r in enumerate(formation.robots) if getattr(r, "law", None) == law)
    follower = formation.robots[index]
    rows = []
    for gain in gains:
        default = getattr(follower, gain)
        for value in grid(default, None):
            changed = dataclasses.replace(follower, **{gain: value})
            if gain == "d" and follower.start is not None:
                # keep the castor point where it starts, so that d does not change the initial errors
                x, y, theta = follower.start
                shift = value - default
                changed = dataclasses.replace(changed, start=(x - shift * math.cos(theta), y - shift * math.sin(theta),
                                                              theta))
            robots = tuple(changed if i == index else r for i, r in enumerate(formation.robots))
            result = simulate_formation(dataclasses.replace(formation, robots=robots))
            m = result.follower_metrics(follower.name)
            first, second = follower.outputs
            row = {"gain": gain, "value": value, "default": default, "x": value / default,
                   f"mean |{first} error|": m[f"{first}_error"]["mean"],
                   f"mean |{second} error|": m[f"{second}_error"]["mean"],
                   "peak |v| (m/s)": m["safety"]["peak_v"], "peak |ω| (rad/s)": m["safety"]["peak_omega"],
                   "closest robot (m)": m["safety"]["min_distance"]}
            if "min_abs_sin_gamma_difference" in m["safety"]:
                row["min |sin(γ1−γ2)|"] = m["safety"]["min_abs_sin_gamma_difference"]
            rows.append(row)
    first = follower.outputs[0]
    return {"rows": rows, "panels": (f"mean |{first} error|", "peak |ω| (rad/s)"),
            "setup": f"the formation study's {case} case (Test 1, leader: dynamic feedback; the follower starts "
                     "away from its place in the formation; when d changes, its axle start moves so that its castor "
                     "point, and so the initial errors, stay the same)"}


# ------------------------------------------------------------------ posture laws

def measure_posture(law: str) -> dict:
    from nonholo.control.posture import posture_controller
    from nonholo.formation import Formation, Leader, simulate_formation

    defaults = dict(posture_controller(law).gains)
    rows = []
    for gain in POSTURE[law]:
        default = defaults[gain]
        for value in grid(default, None):
            leader = Leader("robot", posture_controller(law, **{gain: value}), start=(-10.0, -10.0, 0.0),
                            goal=(0.0, 0.0, 0.0))
            result = simulate_formation(Formation([leader], duration=60.0, dt=0.01))
            x, y, theta = (result.trajectory(f)[0] for f in ("x", "y", "theta"))
            distance = np.hypot(x, y)
            outside = np.flatnonzero(distance >= NEAR)
            near = 0.0 if outside.size == 0 else (math.inf if outside[-1] == distance.size - 1
                                                   else float(result.t[outside[-1] + 1]))
            late = result.t >= result.t[-1] - 10.0
            rows.append({"gain": gain, "value": value, "default": default, "x": value / default,
                         "distance at 60 s (m)": float(distance[-1]),
                         "max distance, last 10 s (m)": float(distance[late].max()), f"within {NEAR:g} m after (s)": near,
                         "heading error at 60 s (°)": abs(math.degrees(math.remainder(float(theta[-1]), 2 * math.pi))),
                         "peak |v| (m/s)": float(np.abs(result.trajectory("v")[0]).max()),
                         "peak |ω| (rad/s)": float(np.abs(result.trajectory("omega")[0]).max())})
    first = "max distance, last 10 s (m)" if law == "time-varying" else f"within {NEAR:g} m after (s)"
    return {"rows": rows, "panels": (first, "peak |ω| (rad/s)"),
            "setup": "a run from (−10, −10), heading 0, to the goal (0, 0) with heading 0, 60 s, dt = 0.01 s"}


# ------------------------------------------------------------------ the index's comparison

def leader_table() -> str:
    """Mean error of every tracking law on the four thesis tests (canonical set-up), and the
    error left at the end of Test 4 (10 m off at the start)."""
    tests = {"test1-eight": "Test 1", "test2-line": "Test 2", "test3-sinusoid": "Test 3", "test4-circle": "Test 4"}
    results = {name: nh.simulate(nh.load_scenario(examples.path(name)), record=False) for name in tests}
    lines = ["| law | " + " | ".join(f"{t} mean" for t in tests.values()) + " | Test 4 e(T) |",
             "|---|" + "---:|" * (len(tests) + 1)]
    for i, robot in enumerate(next(iter(results.values())).scenario.robots):
        law = robot.controller.name
        row = []
        for name, result in results.items():
            j = [r.controller.name for r in result.scenario.robots].index(law)
            row.append(number(result.metrics.error_mean[j]))
        j = [r.controller.name for r in results["test4-circle"].scenario.robots].index(law)
        row.append(number(results["test4-circle"].metrics.error_final[j]))
        lines.append(f"| [`{law}`]({law}.md) | " + " | ".join(row) + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------ output

def number(value) -> str:
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isinf(value)):
        return "never"
    value = float(value)
    return f"{value:.3g}" if value == 0 or 1e-3 <= abs(value) < 1e5 else f"{value:.2e}"


def table(measured: dict) -> str:
    columns = [c for c in measured["rows"][0] if c not in ("gain", "value", "default", "x")]
    header = [c.replace("|", "\\|") for c in columns]  # a literal | would end the markdown cell
    lines = ["| gain | value | " + " | ".join(header) + " |", "|---|---:|" + "---:|" * len(columns)]
    for row in measured["rows"]:
        value = number(row["value"]) + (" (default)" if math.isclose(row["value"], row["default"]) else "")
        lines.append(f"| `{row['gain']}` | {value} | " + " | ".join(number(row[c]) for c in columns) + " |")
    return "\n".join(lines)


def figure(law: str, measured: dict, path: Path) -> None:
    from nonholo.studies.plots import legend_below, plt, series_style

    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.6))
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.3, top=0.8, wspace=0.32)
    gains = list(dict.fromkeys(r["gain"] for r in measured["rows"]))
    for ax, column in zip(axes, measured["panels"]):
        for k, gain in enumerate(gains):
            rows = [r for r in measured["rows"] if r["gain"] == gain]
            x = [r["x"] for r in rows]
            y = [r[column] if math.isfinite(r[column]) else np.nan for r in rows]
            label = "1 + c3" if gain == "c3" else gain
            ax.plot(x, y, marker="o", ms=4, **series_style(k), label=label)
        ax.set(xscale="log", xlabel="gain / its default", title=column)
        ax.set_xticks(FACTORS, [f"×{f:g}" for f in FACTORS])
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        values = [r[column] for r in measured["rows"] if math.isfinite(r[column]) and r[column] > 0]
        if values and max(values) / min(values) > 30:
            ax.set_yscale("log")
        ax.axvline(1.0, color="0.5", lw=0.8, ls=":")
        ax.grid(True, alpha=0.3)
    legend_below(fig, axes[0], ncol=len(gains), fontsize=9)
    fig.suptitle(f"{law}: raising one gain at a time (others at their defaults)", fontsize=11, y=0.98)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def update_page(page: Path, text: str, marker: str = "measured") -> None:
    content = page.read_text(encoding="utf-8")
    begin, end = f"<!-- {marker}:begin -->", f"<!-- {marker}:end -->"
    if begin not in content:
        raise SystemExit(f"{page}: no {begin} marker")
    head, rest = content.split(begin, 1)
    _, tail = rest.split(end, 1)
    page.write_text(f"{head}{begin}\n{text}\n{end}{tail}", encoding="utf-8")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="update the pages' tables and figures")
    parser.add_argument("--only", nargs="*", help="controllers to measure (default: all)")
    args = parser.parse_args()
    jobs = {**{law: measure_tracking for law in TRACKING}, **{law: measure_follower for law in FOLLOWERS},
            **{law: measure_posture for law in POSTURE}}
    if not args.only or "index" in args.only:
        text = leader_table()
        print(f"## index: the tracking laws on the thesis tests\n\n{text}\n", flush=True)
        if args.write:
            update_page(HERE / "README.md", text, "leader-table")
    for law, measure in jobs.items():
        if args.only and law not in args.only:
            continue
        started = time.perf_counter()
        measured = measure(law)
        text = f"Measured on {measured['setup']}:\n\n{table(measured)}"
        print(f"## {law} ({time.perf_counter() - started:.1f} s)\n\n{text}\n", flush=True)
        if args.write:
            update_page(HERE / f"{law}.md", text)
            figure(law, measured, HERE / f"{law}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
