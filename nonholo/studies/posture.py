"""The posture study: thesis §5.7–5.8 (Figures 5.46–5.51) reproduced and compared.

* the three posture stabilisers (time-varying, polar, dynamic-feedback-posture) with the
  thesis's gains (Eq 5.12–5.14, the bundled ``posture-*.toml`` examples) from (−10, −10),
  heading 0, to the goals (0, 0) and (−10, 10), heading 0, for 60 s;
* the variants that explain §5.8: the polar law without goal translation and with the
  distance measured from the world origin (spec §5.2 (a), (b)), the dynamic-feedback law
  with ξ(0) = −0.1, the time-varying law over 120 s;
* tables beside the thesis's statements and the spec's reference numbers (§6 (d)),
  "differences from the thesis" generated from them.

Quick mode (``--quick``): dt = 0.02 s instead of 0.01 s.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numba import njit

from nonholo import examples, load_scenario
from nonholo.control.posture import POSTURE_CONTROLLERS, goal_frame_pose, polar_command
from nonholo.formation import Formation, FormationResult, simulate_formation
from nonholo.models.formation_geometry import wrap
from nonholo.studies.base import Study, StudyOptions, run_briefly
from nonholo.studies.forking import draw_now
from nonholo.studies.formation import QUICK_DT
from nonholo.studies.framework import (COMPARISON_COLUMNS, Agreement, Column, Comparison, Finding, SpecValue,
                                       TabulatedStudyResult, Table, show)

LAWS = ("time-varying", "polar", "dynamic-feedback-posture")
EXAMPLES = {"time-varying": "posture-time-varying", "polar": "posture-polar",
            "dynamic-feedback-posture": "posture-dynamic-feedback"}
LABELS = {"time-varying": "time-varying", "polar": "polar", "dynamic-feedback-posture": "dynamic FL"}
NEAR = 0.1  # m: "within reach" of the goal, for the approach times
CONVERGED = 1e-6  # m: a final distance below this is "converged"
LONG_DURATION = 120.0  # s: the time-varying law's slow convergence, measured further

# ------------------------------------------------------------------ thesis data (never read at run time)
# Source: S. Ahmed, MSc thesis (UTP), §5.7–5.8: start (−10, −10), goals (0, 0) and (−10, 10)
# (headings not given: 0 here, as in the spec), gains Eq 5.12–5.14, figures only (no numbers).
START = (-10.0, -10.0, 0.0)
GOALS = {"origin": (0.0, 0.0, 0.0), "(-10, 10)": (-10.0, 10.0, 0.0)}
THESIS_FIGURES = {("time-varying", "origin"): "Fig 5.46", ("time-varying", "(-10, 10)"): "Fig 5.47",
                  ("polar", "origin"): "Fig 5.48", ("polar", "(-10, 10)"): "Fig 5.49",
                  ("dynamic-feedback-posture", "origin"): "Fig 5.50",
                  ("dynamic-feedback-posture", "(-10, 10)"): "Fig 5.51"}
THESIS_GAINS = {"time-varying": {"k1": 0.5, "k2": 2.0, "k3": 1.0, "k5": 1.0, "k6": 50.0},  # Eq 5.12 (k2 printed k4)
                "polar": {"k1": 1.0, "k2": 3.0, "k3": 2.0},  # Eq 5.13
                "dynamic-feedback-posture": {"kp1": 2.0, "kd1": 3.0, "kp2": 12.0, "kd2": 7.0}}  # Eq 5.14
# §5.8, per law: what the thesis says happens (it names the time-varying law "nonlinear").
THESIS_POLAR_FAILS = ("the posture stabilization feedback controller based on polar coordinates fails to eliminate "
                      "the error between the desired and the actual goal point ... (-10, 10) ... near to the goal "
                      "point, still it does not converge")
THESIS_OTHERS_SUCCEED = ("the robot achieves the correct goal configuration using the nonlinear and dynamic feedback "
                         "linearized controller")
THESIS_STATEMENTS = {("polar", "(-10, 10)"): "near the goal, does not converge",
                     ("polar", "origin"): "(no statement)"} | {
    (law, goal): "achieves the correct goal configuration" for law in ("time-varying", "dynamic-feedback-posture")
    for goal in GOALS}

# Source: shared spec follower-posture.md §6 (d) (start (−10, −10, 0), goal heading 0, 60 s, RK4 dt = 0.01 s)
# and §5.1–5.3. The time-varying law's values are integration-sensitive to a few mm (slow, oscillating
# convergence); the polar law stops at its tolerance (1e-9 m).
SPEC_REFERENCE: dict[str, dict[str, SpecValue]] = {
    "time-varying origin": {"distance": SpecValue.approx(0.072, abs_=0.004, text="0.072 m", sensitive=True),
                            "heading_deg": SpecValue("0.03°", 0.0, 0.06, sensitive=True)},
    "time-varying (-10, 10)": {"distance": SpecValue.approx(0.073, abs_=0.004, text="0.073 m", sensitive=True),
                               "heading_deg": SpecValue("0.04°", 0.0, 0.06, sensitive=True)},
    "time-varying origin, 120 s": {"distance": SpecValue.approx(0.0175, abs_=0.004, text="0.0175 m", sensitive=True)},
    "polar origin": {"distance": SpecValue.below(1e-9, "< 1e-9 m"), "heading_deg": SpecValue.below(1e-7, "< 1e-7°"),
                     "near_time": SpecValue.approx(5.3, abs_=0.05, text="5.3 s to 0.1 m")},
    "polar (-10, 10)": {"distance": SpecValue.below(1e-9, "< 1e-9 m"), "heading_deg": SpecValue.below(1e-7, "< 1e-7°"),
                        "near_time": SpecValue.approx(6.3, abs_=0.05, text="6.3 s to 0.1 m")},
    "polar, goal untranslated": {"distance": SpecValue.approx(14.14, abs_=0.01, text="14.14 m")},
    "polar, distance from the world origin": {
        "distance": SpecValue("0.03 m (hovering; step-size dependent)", 1e-3, 0.035, sensitive=True),
        "heading_deg": SpecValue.approx(179.0, abs_=2.0, text="179°", sensitive=True)},
    "dynamic FL origin": {"distance": SpecValue.below(1e-10, "2e-25 m"), "heading_deg": SpecValue.below(0.1, "0°")},
    "dynamic FL (-10, 10)": {"distance": SpecValue.below(1e-10, "≈ 0 m"),
                             "heading_deg": SpecValue.approx(180.0, abs_=0.1, text="180°")},
    "dynamic FL origin, ξ(0) = −0.1": {"distance": SpecValue.below(1e-10, "2e-25 m"),
                                       "heading_deg": SpecValue.approx(180.0, abs_=0.1, text="180°")},
    "dynamic FL (-10, 10), ξ(0) = −0.1": {"distance": SpecValue.below(1e-10, "≈ 0 m"),
                                          "heading_deg": SpecValue.approx(180.0, abs_=0.1, text="180°")},
}


# ------------------------------------------------------------------ the implementation error of spec §5.2 (b)

@njit(error_model="numpy", fastmath=False)
def polar_world_distance_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """The polar law with ψ measured from the *world* origin while φ, μ are goal-relative:
    spec §5.2 (b), a plausible reconstruction of the thesis's §5.8 failure (not a real law)."""
    gx, gy, gtheta = goal_frame_pose(x, y, theta, gains)
    return polar_command(math.sqrt(x * x + y * y), gx, gy, gtheta, gains)


WORLD_DISTANCE = "world-distance"
# The polar controller with the faulty law as an extra variant (same gains, same name, so results
# report it as the polar law with that variant). It reads the world frame: integrated in world
# coordinates (``goal_relative=False``).
POLAR_WITH_FAULT = dataclasses.replace(POSTURE_CONTROLLERS["polar"], goal_relative=False,
                                       laws={**POSTURE_CONTROLLERS["polar"].laws, WORLD_DISTANCE: polar_world_distance_law})


# ------------------------------------------------------------------ the cases

def _example(law: str) -> Formation:
    return load_scenario(examples.path(EXAMPLES[law]))


def _with(formation: Formation, name: str, goal=None, controller=None, **changes) -> Formation:
    leader = formation.leaders[0]
    leader = dataclasses.replace(leader, goal=goal or leader.goal, controller=controller or leader.controller)
    return dataclasses.replace(formation, robots=(leader,), name=name, **changes)


def case_key(law: str, goal: str) -> str:
    return f"{LABELS[law]} {goal}"


def build_cases(quick: bool = False) -> dict[str, Formation]:
    """The six thesis runs (3 laws × 2 goals) and the variants of spec §5.2–5.3, §6 (d)."""
    cases = {}
    for law in LAWS:
        example = _example(law)
        for goal, pose in GOALS.items():
            cases[case_key(law, goal)] = _with(example, case_key(law, goal), goal=pose)
    polar, dfl, tv = (_example(law) for law in ("polar", "dynamic-feedback-posture", "time-varying"))
    gains = dict(polar.leaders[0].controller.gains)
    cases["polar, distance from the world origin"] = _with(
        polar, "polar, distance from the world origin", controller=POLAR_WITH_FAULT.configure(gains, WORLD_DISTANCE))
    kick = dict(dfl.leaders[0].controller.gains, xi0=-abs(dfl.leaders[0].controller.xi0))
    for goal, pose in GOALS.items():
        name = f"dynamic FL {goal}, ξ(0) = −{abs(kick['xi0']):g}"
        cases[name] = _with(dfl, name, goal=pose, controller=POSTURE_CONTROLLERS["dynamic-feedback-posture"].configure(kick))
    cases["time-varying origin, 120 s"] = _with(tv, "time-varying origin, 120 s", goal=GOALS["origin"],
                                                duration=LONG_DURATION)
    if quick:
        cases = {k: dataclasses.replace(c, dt=QUICK_DT) for k, c in cases.items()}
    return cases


all_cases = build_cases


def simulate_cases(quick: bool = False) -> dict[str, FormationResult]:
    return {key: simulate_formation(formation) for key, formation in all_cases(quick).items()}


# ------------------------------------------------------------------ numbers

def goal_distance(result: FormationResult, goal) -> np.ndarray:
    return np.hypot(result.trajectory("x")[0] - goal[0], result.trajectory("y")[0] - goal[1])


def time_within(t: np.ndarray, distance: np.ndarray, radius: float) -> float | None:
    """First time after which the distance stays below ``radius`` (None if it never does)."""
    outside = np.flatnonzero(distance >= radius)
    if outside.size == 0:
        return 0.0
    return None if outside[-1] == distance.size - 1 else float(t[outside[-1] + 1])


def posture_record(key: str, result: FormationResult, goal=None) -> dict:
    """Final distance to ``goal`` (default: the run's own goal), heading error, approach time.
    The final distance to the run's own goal is the simulator's, computed where the run was
    integrated (with the goal as origin: to the last bit, not to the 2e-15 m of a world
    coordinate near (−10, 10))."""
    leader = result.formation.leaders[0]
    own = goal is None or tuple(goal) == tuple(leader.goal)
    goal = tuple(goal or leader.goal)
    distance = goal_distance(result, goal)
    final = result.posture_metrics(leader.name)["position_error"]["final"] if own else float(distance[-1])
    heading = abs(float(wrap(result.trajectory("theta")[0, -1] - goal[2])))
    late = result.t >= result.t[-1] - 10.0
    return {"case": key, "law": leader.controller.name, "variant": leader.controller.variant,
            "goal": f"({goal[0]:g}, {goal[1]:g})", "T": float(result.t[-1]), "distance": final,
            "distance_late_max": float(distance[late].max()), "heading_deg": math.degrees(heading),
            "near_time": time_within(result.t, distance, NEAR),
            "peak_v": float(np.abs(result.trajectory("v")[0]).max()),
            "peak_omega": float(np.abs(result.trajectory("omega")[0]).max()),
            "heading_controlled": result.posture_metrics(leader.name)["heading_controlled"]}


def literal_excitation_log10(e2: float, k5: float, k6: float) -> float:
    """log10 of |g| from Eq 5.11 as printed, (e^(k6 e2) − 1)/(e^(k5 e2) + 1) (|sin t| = 1),
    computed in logs because the value itself overflows."""
    if e2 <= 0:
        return math.log10(1.0)
    return (k6 * e2 + math.log1p(-math.exp(-k6 * e2)) - k5 * e2 - math.log1p(math.exp(-k5 * e2))) / math.log(10)


def initial_lateral_error(start, goal) -> float:
    """|e2(0)| of the time-varying law: x_d(0) = 0 on the goal's x-axis (spec §5.1)."""
    dx, dy = start[0] - goal[0], start[1] - goal[1]
    c, s = math.cos(goal[2]), math.sin(goal[2])
    gx, gy, gt = c * dx + s * dy, -s * dx + c * dy, start[2] - goal[2]
    return abs(-math.sin(gt) * (0.0 - gx) + math.cos(gt) * (0.0 - gy))


# ------------------------------------------------------------------ the result

class PostureStudyResult(TabulatedStudyResult):
    name = "posture"
    title = "Posture stabilization: thesis §5.7–5.8 reproduced (Figures 5.46–5.51)"
    spec_file = "follower-posture.md"

    def __init__(self, runs: dict[str, FormationResult], quick: bool, elapsed_s: float):
        self.runs, self.quick, self.elapsed_s = runs, quick, elapsed_s
        self.records = {key: posture_record(key, run) for key, run in runs.items()}
        # spec §5.2 (a): no goal translation = the run to the origin, judged against (−10, 10)
        untranslated = posture_record("polar, goal untranslated", runs[case_key("polar", "origin")],
                                      goal=GOALS["(-10, 10)"])
        self.records[untranslated["case"]] = untranslated
        self.comparisons = [Comparison(case, quantity, self.records[case].get(quantity), spec)
                            for case, refs in SPEC_REFERENCE.items() for quantity, spec in refs.items()
                            if case in self.records]
        self.findings = derive_findings(self)

    def record(self, law: str, goal: str) -> dict:
        return self.records[case_key(law, goal)]

    def tables(self) -> list[Table]:
        main = [dict(self.record(law, goal), figure=THESIS_FIGURES[(law, goal)],
                     thesis=THESIS_STATEMENTS[(law, goal)]) for law in LAWS for goal in GOALS]
        variants = [r for k, r in self.records.items() if k not in {case_key(l, g) for l in LAWS for g in GOALS}]
        columns = [Column("case", "case"), Column("goal", "goal", terminal=False), Column("T (s)", "T", terminal=False),
                   Column("final distance (m)", "distance"),
                   Column("max distance, last 10 s (m)", "distance_late_max", terminal=False),
                   Column("final heading error", "heading_deg", lambda v: f"{v:.3g}°"),
                   Column(f"within {NEAR:g} m after (s)", "near_time"),
                   Column("peak |v| (m/s)", "peak_v", terminal=False), Column("peak |ω| (rad/s)", "peak_omega", terminal=False)]
        return [
            Table("runs", "Thesis runs from (−10, −10), heading 0, to each goal with heading 0, beside the thesis's "
                  "statements (§5.8; it prints no numbers); distance and heading error at the end",
                  [columns[0], Column("thesis (§5.8)", "thesis"), Column("distance (m)", "distance"),
                   Column("heading error", "heading_deg", lambda v: f"{v:.3g}°"), columns[1],
                   Column("thesis figure", "figure", terminal=False), *columns[2:3], *columns[4:5], *columns[6:],
                   Column("heading controlled", "heading_controlled", terminal=False)], main),
            Table("variants", "Variants that explain §5.8 (spec §5.2 (a)/(b), §5.3, §5.1)", columns, variants),
            Table("spec", "Our numbers beside the spec's reference numbers (follower-posture.md §6 (d))",
                  COMPARISON_COLUMNS, [c.record() for c in self.comparisons], terminal=False),
        ]

    def setup_text(self) -> str:
        run = self.runs[case_key("polar", "origin")]
        text = (f"Start (−10, −10) with heading 0; goals (0, 0) and (−10, 10) with heading 0 (the thesis gives no "
                f"headings); 60 s; the bundled posture-*.toml examples with the thesis's gains: time-varying "
                f"{_gains(THESIS_GAINS['time-varying'])} (Eq 5.12), polar {_gains(THESIS_GAINS['polar'])} (Eq 5.13), "
                f"dynamic FL {_gains(THESIS_GAINS['dynamic-feedback-posture'])} (Eq 5.14) with ξ(0) = +0.1 m/s. Every "
                f"law works in goal-frame coordinates (spec §5; the thesis uses raw x, y). RK4, dt = "
                f"{run.formation.dt:g} s, automatic sub-steps. Headings are wrapped to (−180°, 180°].")
        if self.quick:
            text += f" QUICK MODE: dt = {QUICK_DT} s (not the canonical numbers)."
        return text

    def write_figures(self, folder: Path, draw: Callable = draw_now) -> list[tuple[str, str]]:
        draw(plot_posture_runs, self, folder / "posture-runs.png")
        draw(plot_posture_inputs, self, folder / "posture-inputs.png")
        draw(plot_polar_variants, self, folder / "polar-variants.png")
        return [("posture-runs.png", "The three laws to both goals (Figures 5.46–5.51): paths, distance to the goal "
                                     "and heading over time."),
                ("posture-inputs.png", "What each law applies: driving speed v and turn rate ω to both goals; "
                                       "start-up peaks outside a column's scale (the dynamic-feedback law's first "
                                       "turn from rest) are clipped and named above the panel."),
                ("polar-variants.png", "Thesis §5.8's polar “failure” for goal (−10, 10): the correct law, the goal not "
                                       "translated, and the distance measured from the world origin.")]


def _gains(gains: dict) -> str:
    return "(" + ", ".join(f"{k} = {v:g}" for k, v in gains.items()) + ")"


# ------------------------------------------------------------------ findings

def derive_findings(result: PostureStudyResult) -> list[Finding]:
    return [_polar_claim(result), _time_varying_claim(result), _dynamic_feedback_claim(result),
            _eq_5_11(result), _spec_agreement(result)]


def _polar_claim(result: PostureStudyResult) -> Finding:
    correct = result.record("polar", "(-10, 10)")
    untranslated = result.records["polar, goal untranslated"]
    fault = result.records["polar, distance from the world origin"]
    converged = correct["distance"] < CONVERGED
    hovers = fault["distance"] < 1.0 and fault["distance_late_max"] > CONVERGED
    return Finding(f"Thesis §5.8: “{THESIS_POLAR_FAILS}”", "fails" if converged else "holds",
                   f"the polar law reaches (−10, 10): final distance {correct['distance']:.1e} m, heading error "
                   f"{correct['heading_deg']:.1e}°, within {NEAR:g} m after {show(correct['near_time'])} s (goal "
                   f"origin: {result.record('polar', 'origin')['distance']:.1e} m). The failure appears only with an "
                   f"implementation error: without goal translation the robot parks at the origin, "
                   f"{untranslated['distance']:.2f} m from (−10, 10); with the distance measured from the world origin "
                   f"it ends {fault['distance'] * 1000:.0f} mm from the goal (up to {fault['distance_late_max'] * 1000:.0f} "
                   f"mm in the last 10 s) with heading error {fault['heading_deg']:.0f}°"
                   + (" — near the goal without converging, as the thesis describes." if hovers else "."),
                   "Eq 4.52 writes μ = tan⁻¹(y/x) − θ + π in raw coordinates: the law is stated for a goal at the "
                   "origin and needs the pose in the goal frame (errata 11, 28; spec §5.2). The mixed-frame reading is "
                   "a plausible reconstruction, not a documented fact.")


def _time_varying_claim(result: PostureStudyResult) -> Finding:
    runs = [result.record("time-varying", goal) for goal in GOALS]
    longer = result.records["time-varying origin, 120 s"]
    return Finding(f"Thesis §5.8: “{THESIS_OTHERS_SUCCEED}” — time-varying (“nonlinear”) law", "partly",
                   "after 60 s the robot is " + ", ".join(f"{r['distance']:.3f} m from {r['goal']} (heading error "
                                                          f"{r['heading_deg']:.2f}°)" for r in runs)
                   + f"; after 120 s {longer['distance']:.4f} m. It converges, slowly and not exponentially: the "
                   f"distance oscillates, reaching {runs[0]['distance_late_max']:.3f} m during the last 10 s of the "
                   f"60 s run and still {longer['distance_late_max']:.3f} m during the last 10 s of the 120 s run.",
                   "smooth time-varying feedback converges slowly by nature; the distance oscillates while it shrinks "
                   "(spec §5.1). Eq 5.11 as printed cannot be used (see below); the thesis's Eq 5.12 calls the e2 "
                   "gain k4 (erratum 10).")


def _dynamic_feedback_claim(result: PostureStudyResult) -> Finding:
    runs = [result.record("dynamic-feedback-posture", goal) for goal in GOALS]
    wrong = [r for r in runs if r["heading_deg"] > 1.0]
    return Finding(f"Thesis §5.8: “{THESIS_OTHERS_SUCCEED}” — dynamic FL law",
                   "partly" if wrong else "holds",
                   "position: " + ", ".join(f"{r['distance']:.1e} m from {r['goal']}" for r in runs)
                   + "; heading error: " + ", ".join(f"{r['heading_deg']:.2f}° at {r['goal']}" for r in runs)
                   + (f". The goal heading is missed by 180° at {', '.join(r['goal'] for r in wrong)}" if wrong else "")
                   + ". With ξ(0) = −0.1 the final heading errors are "
                   + ", ".join(f"{r['heading_deg']:.1f}°" for k, r in result.records.items() if "ξ(0)" in k)
                   + ". Starting from rest needs ξ(0) ≠ 0 and a fast initial turn: peak |ω| "
                   + ", ".join(f"{r['peak_omega']:.0f} rad/s" for r in runs) + ".",
                   "the law regulates the position only: the robot arrives along the goal's x-axis and the sign of the "
                   "initial x-velocity mode decides between θ_g and θ_g + π (errata 13, 29; spec §5.3).")


def _eq_5_11(result: PostureStudyResult) -> Finding:
    gains = THESIS_GAINS["time-varying"]
    sizes = {goal: initial_lateral_error(START, pose) for goal, pose in GOALS.items()}
    logs = {goal: literal_excitation_log10(e2, gains["k5"], gains["k6"]) for goal, e2 in sizes.items()}
    one = literal_excitation_log10(1.0, gains["k5"], gains["k6"])
    return Finding("Eq 5.11: g(e, t) = (exp(k6 e2) − 1)/(exp(k5 e2) + 1) sin t", "fails",
                   f"as printed, |g| reaches 10^{one:.1f} at e2 = 1 m and "
                   + ", ".join(f"10^{logs[goal]:.0f} at the initial e2 = {sizes[goal]:g} m (goal {goal})"
                               for goal in GOALS)
                   + " — beyond double precision (10^308) and unusable as a speed; the corrected "
                   "g = tanh(k6 e2/2) sin t is bounded by 1 and the runs above use it.",
                   "k5 in the denominator's exponent must be k6 (erratum 25, spec §5.1).")


def _spec_agreement(result: PostureStudyResult) -> Finding:
    agreement = Agreement.of(result.comparisons)
    missing = agreement.missing
    reasons = ["QUICK MODE: the coarser grid moves the slow time-varying runs."] if result.quick and missing else []
    if any(c.case.startswith("polar") and c.quantity == "heading_deg" for c in missing):
        reasons.append(_polar_stop_note(result))
    return Finding("Spec reference numbers (follower-posture.md §6 (d))", "holds" if not missing else "partly",
                   agreement.counts()
                   + ("; not " + ", ".join(f"{c.case} {c.quantity} (ours {show(c.ours)}, spec {c.spec.text})"
                                           for c in missing) if missing else "") + ".", " ".join(reasons))


def _polar_stop_note(result: PostureStudyResult) -> str:
    """When and with which heading error the polar runs stopped (v = ω = 0 below the tolerance)."""
    parts = []
    for goal, pose in GOALS.items():
        run = result.runs[case_key("polar", goal)]
        tolerance = run.formation.leaders[0].controller.gains["tolerance"]
        stop = time_within(run.t, goal_distance(run, pose), tolerance)
        heading = abs(math.degrees(float(wrap(run.trajectory("theta")[0, -1] - pose[2]))))
        parts.append(f"goal {goal} at t = {show(stop)} s with heading error {heading:.2g}°")
    return (f"the polar law stops (v = ω = 0) once the distance is below its tolerance "
            f"({tolerance:g} m), freezing the heading error it has then: " + "; ".join(parts)
            + ". The spec's reference run does not state its stop rule.")


# ------------------------------------------------------------------ figures

LAW_COLORS = {"time-varying": "tab:blue", "polar": "tab:orange", "dynamic-feedback-posture": "tab:green"}


def plot_posture_runs(result: PostureStudyResult, path: Path) -> None:
    """Figures 5.46–5.51 in one: paths to each goal, distance to the goal, heading."""
    from nonholo.studies.plots import legend_below, plt, save_figure

    fig, axes = plt.subplots(2, 2, figsize=(13, 11))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.92, wspace=0.2, hspace=0.42)
    ax_origin, ax_other, ax_distance, ax_heading = axes.ravel()
    for ax, goal in ((ax_origin, "origin"), (ax_other, "(-10, 10)")):
        for law in LAWS:
            run = result.runs[case_key(law, goal)]
            ax.plot(run.trajectory("x")[0], run.trajectory("y")[0], color=LAW_COLORS[law], lw=1.6,
                    label=f"{LABELS[law]} ({THESIS_FIGURES[(law, goal)]})")
        pose = GOALS[goal]
        ax.plot(*START[:2], "ks", ms=8, label="start (−10, −10), heading 0")
        ax.plot(*pose[:2], "r*", ms=16, label=f"goal ({pose[0]:g}, {pose[1]:g}), heading 0")
        ax.set(xlabel="x (m)", ylabel="y (m)", title=f"Paths to the goal ({pose[0]:g}, {pose[1]:g})")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.1), ncol=2, frameon=False)
    for law in LAWS:
        for goal, style in (("origin", "-"), ("(-10, 10)", (0, (5, 2)))):
            run = result.runs[case_key(law, goal)]
            distance = np.maximum(goal_distance(run, GOALS[goal]), 1e-12)
            ax_distance.semilogy(run.t, distance, color=LAW_COLORS[law], ls=style, lw=2.2 if goal == "origin" else 1.3,
                                 label=f"{LABELS[law]}, goal {goal}")
            ax_heading.plot(run.t, np.degrees(wrap(run.trajectory("theta")[0])), color=LAW_COLORS[law], ls=style,
                            lw=2.2 if goal == "origin" else 1.3, label=f"{LABELS[law]}, goal {goal}")
    ax_distance.set(xlabel="time t (s)", ylabel="distance to the goal (m, log scale; floor 1e-12)",
                    title="Distance to the goal", ylim=(1e-12, 50))
    ax_heading.axhline(0.0, color="k", lw=0.8)
    ax_heading.set(xlabel="time t (s)", ylabel="heading θ (degrees, wrapped)", title="Heading (goal heading 0°)",
                   ylim=(-190, 190), yticks=range(-180, 181, 60))
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    legend_below(fig, ax_distance, ncol=6, fontsize=8.5)
    fig.suptitle("Posture stabilization from (−10, −10): time-varying, polar and dynamic FL laws (60 s)", fontsize=14)
    save_figure(fig, path)


def plot_posture_inputs(result: PostureStudyResult, path: Path) -> None:
    """Small multiples, one row per law: the applied v and ω to each goal (solid: (0, 0),
    dashed: (−10, 10)); start-up spikes are clipped and named above the panel."""
    from nonholo.studies.plots import legend_below, peak_note, plt, robust_range, save_figure

    fig, axes = plt.subplots(len(LAWS), 2, figsize=(13, 9.5), sharex=True, sharey="col", squeeze=False)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.9, wspace=0.15, hspace=0.55)
    for c, (field, unit, kind) in enumerate((("v", "m/s", "applied v"), ("omega", "rad/s", "applied ω"))):
        series = {(law, goal): result.runs[case_key(law, goal)].trajectory(field)[0] for law in LAWS for goal in GOALS}
        low, high = robust_range(list(series.values()))
        for r, law in enumerate(LAWS):
            ax = axes[r, c]
            notes = []
            for goal, style in (("origin", "-"), ("(-10, 10)", (0, (5, 2)))):
                run = result.runs[case_key(law, goal)]
                ax.plot(run.t, series[(law, goal)], color=LAW_COLORS[law], ls=style, lw=2.2 if goal == "origin" else 1.2,
                        label=f"goal {goal}")
                note = peak_note(run.t, series[(law, goal)], low, high, unit)
                if note:
                    notes.append(f"goal {goal}: {note}")
            ax.set_title(f"{LABELS[law]}: {kind} ({unit})" + "".join(f"\n{n}" for n in notes), fontsize=9,
                         color="#a31515" if notes else "black")
            ax.grid(True, alpha=0.3)
        axes[0, c].set_ylim(low, high)
        axes[-1, c].set_xlabel("time t (s)")
    legend_below(fig, axes[0, 0], ncol=2)
    fig.suptitle("Posture stabilization: what each law applies (solid: goal (0, 0); dashed: goal (−10, 10))",
                 fontsize=13)
    save_figure(fig, path)


def plot_polar_variants(result: PostureStudyResult, path: Path) -> None:
    from nonholo.studies.plots import legend_below, plt, save_figure

    goal = GOALS["(-10, 10)"]
    runs = {"correct (goal frame)": result.runs[case_key("polar", "(-10, 10)")],
            "goal not translated (parks at the origin)": result.runs[case_key("polar", "origin")],
            "distance from the world origin": result.runs["polar, distance from the world origin"]}
    colors = ("tab:orange", "tab:gray", "tab:purple")
    fig, (ax_path, ax_distance) = plt.subplots(1, 2, figsize=(13, 6))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.2, top=0.86, wspace=0.22)
    for (label, run), color in zip(runs.items(), colors):
        ax_path.plot(run.trajectory("x")[0], run.trajectory("y")[0], color=color, lw=1.6, label=label)
        ax_distance.semilogy(run.t, np.maximum(goal_distance(run, goal), 1e-12), color=color, lw=1.4, label=label)
    ax_path.plot(*START[:2], "ks", ms=8, label="start")
    ax_path.plot(*goal[:2], "r*", ms=16, label="goal (−10, 10)")
    ax_path.set(xlabel="x (m)", ylabel="y (m)", title="Paths")
    ax_path.set_aspect("equal", adjustable="datalim")
    ax_distance.set(xlabel="time t (s)", ylabel="distance to (−10, 10) (m, log scale)", ylim=(1e-12, 50),
                    title="Distance to the goal (−10, 10)")
    for ax in (ax_path, ax_distance):
        ax.grid(True, alpha=0.3)
    legend_below(fig, ax_path, ncol=5, fontsize=9)
    fig.suptitle("Polar law, goal (−10, 10): the thesis's “does not converge” needs an implementation error",
                 fontsize=13)
    save_figure(fig, path)


# ------------------------------------------------------------------ running

def run_posture(options: StudyOptions) -> PostureStudyResult:
    started = time.perf_counter()
    cases = all_cases(options.quick)
    runs = {}
    with options.progress_for("study posture", len(cases), "runs") as progress:
        for key, case in cases.items():
            progress.start(key)
            runs[key] = simulate_formation(case)
            progress.done()
    return PostureStudyResult(runs, options.quick, time.perf_counter() - started)


STUDY = Study(
    name="posture", title=PostureStudyResult.title,
    summary="time-varying, polar and dynamic-FL posture laws from (-10,-10) to (0,0) and (-10,10); thesis §5.7-5.8",
    run=run_posture,
    warm_up=lambda options: run_briefly(all_cases(options.quick).values()),
    order=3,
)
