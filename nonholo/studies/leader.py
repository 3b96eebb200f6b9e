"""The leader study: the thesis's Chapter 5 leader experiments reproduced and compared.

* Tests 1–4 × the five thesis controllers (+ offset-point as a sixth column) with the
  spec's canonical set-up (leader.md §5.1: the bundled ``test*.toml`` examples), statistics
  on the uniform grid and over the accepted steps of a Simulink-like variable-step solver
  (``nonholo.studies.solver_steps``), next to Tables 5.2–5.5 (``thesis_values``);
* the gain sweeps of Table 5.6 on Test 1, each one batch, with the trend of the mean error
  classified from the data (``sweep.classify_trend``);
* "differences from the thesis": findings computed from those numbers, with the reasons
  the spec gives (§5.3–5.5, errata 20–24).

Quick mode (``--quick``): N = 10⁴ instead of 10⁵ steps per test and 7-point sweeps (the
uniform-grid numbers move by ≤ 0.3 %, the stiff cascaded cells by up to ~6 %, spec §5.2).
"""
from __future__ import annotations

import csv
import dataclasses
import functools
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nonholo import examples
from nonholo import load_scenario, simulate
from nonholo.studies import thesis_values as thesis
from nonholo.studies.base import Study, StudyOptions, StudyResult
from nonholo.studies.forking import ForkedCall, draw_now
from nonholo.studies.framework import (TERMINAL_WIDTH, Finding, agreement_score, findings_text, fitted_table, fmt,
                                       log_ratio, wrap)
from nonholo.studies.report import escape, html_figure, html_list, html_table
from nonholo.studies.solver_steps import SolverStepResult, solver_step_statistics
from nonholo.studies.sweep import GainAxis, SweepResult, SweepSpec, Trend, run_sweeps

EXAMPLES = {"T1": "test1-eight", "T2": "test2-line", "T3": "test3-sinusoid", "T4": "test4-circle"}
TEST_TITLES = {"T1": "Test 1: figure eight", "T2": "Test 2: straight line", "T3": "Test 3: sinusoid",
               "T4": "Test 4: circle, robot starting at its centre"}
# The path panel shows only the start of long, thin references.
PATH_WINDOW = {"T1": None, "T2": 20.0, "T3": 25.0, "T4": None}
# The v, ω and heading-error panels show the first seconds, where the controllers differ.
INPUT_WINDOW = {"T1": 60.0, "T2": 20.0, "T3": 25.0, "T4": 60.0}
CONTROLLERS = (*thesis.THESIS_CONTROLLERS, "offset-point")
LABELS = {"approximate-linearization": "approx. lin.", "nonlinear": "nonlinear", "cascaded": "cascaded",
          "kanayama": "stable tracking", "dynamic-feedback": "dynamic FL", "offset-point": "offset point"}
QUICK_STEPS = 10_000
CONVERGED = 1e-3  # m: "converged" means the error stays below this
FAILED_FRACTION = 0.1  # a run "fails" if e(T) is still above this fraction of e(0)
CLOSE = math.log(1.15)  # |ln(ours/thesis)| within this: "reproduced" (15 %)
FAR = math.log(10.0)  # beyond this: "off by more than 10×"

# Table 5.6 sweeps on Test 1 (the thesis's ranges are in figures we do not have): each gain
# from START to STOP, the others at their Table 5.1 values.
SWEEP_RANGES = {
    ("approximate-linearization", "zeta"): (0.1, 0.9), ("approximate-linearization", "b"): (0.5, 10.0),
    ("nonlinear", "zeta"): (0.1, 0.9), ("nonlinear", "b"): (0.5, 10.0),
    ("cascaded", "c1"): (50.0, 500.0), ("cascaded", "c2"): (0.5, 5.0), ("cascaded", "c3"): (-0.9, 2.0),
    ("kanayama", "kx"): (1.0, 20.0), ("kanayama", "ky"): (0.001, 0.03), ("kanayama", "ktheta"): (0.04, 0.64),
    ("dynamic-feedback", "kd1"): (0.2, 3.0), ("dynamic-feedback", "kd2"): (0.2, 3.0),
    ("dynamic-feedback", "kp1"): (0.2, 5.0), ("dynamic-feedback", "kp2"): (0.2, 5.0),
}
SWEEP_POINTS, QUICK_SWEEP_POINTS = 41, 7
SWEEP_TEST = "T1"


@dataclass(frozen=True)
class Cell:
    """One test × controller: our statistics (uniform grid and, if taken, solver steps)
    and the thesis's (None for offset-point)."""

    test: str
    controller: str
    uniform: dict
    solver: dict | None
    thesis: dict | None

    def ratio(self, statistic: str = "mean", sampling: str = "uniform") -> float | None:
        ours = self.uniform if sampling == "uniform" else self.solver
        if ours is None or self.thesis is None:
            return None
        return ours[statistic] / self.thesis[statistic]


@dataclass(frozen=True)
class GainEffect:
    """One row of Table 5.6: the thesis's claim and the trend in our sweep."""

    controller: str
    gain: str
    claim: str
    claim_text: str
    default: float
    sweep: SweepResult

    @property
    def trend(self) -> Trend:
        return self.sweep.trend()

    @property
    def agrees(self) -> bool:
        return self.trend.agrees_with(self.claim)


# ---------------------------------------------------------------------------------- running

def canonical_scenario(test: str, quick: bool):
    scenario = load_scenario(examples.path(EXAMPLES[test]))
    return dataclasses.replace(scenario, dt=None, steps=QUICK_STEPS) if quick else scenario


def _simulate_test(test: str, quick: bool):
    scenario = canonical_scenario(test, quick)
    return simulate(scenario, record=True, progress=False)


def simulate_gain_effects(quick: bool) -> list[GainEffect]:
    """Every Table 5.6 sweep on Test 1, simulated together as one batch."""
    scenario = canonical_scenario(SWEEP_TEST, quick)
    points = QUICK_SWEEP_POINTS if quick else SWEEP_POINTS
    robots = {r.controller.name: r for r in scenario.robots}
    specs = [SweepSpec((GainAxis.linear(gain, *SWEEP_RANGES[(controller, gain)], points),), robots[controller].name)
             for controller, gain, *_ in thesis.GAIN_EFFECTS]
    sweeps = run_sweeps(scenario, specs, progress=False)
    return [GainEffect(controller, gain, claim, text, robots[controller].controller.gains[gain], sweep)
            for (controller, gain, claim, text), sweep in zip(thesis.GAIN_EFFECTS, sweeps)]


def _statistics(metrics: dict) -> dict:
    error = metrics["error"]
    return {k: error[k] for k in ("mean", "std", "var", "rms", "max", "final")}


def run_leader(options: StudyOptions) -> "LeaderStudyResult":
    """Run everything (progress over the tasks unless ``options.progress`` is False)."""
    started = time.perf_counter()
    solver = options.sampling in ("solver-steps", "both")
    tasks: list[tuple[str, Callable[[], object]]] = []
    for test in EXAMPLES:
        tasks.append((f"simulate {test}", lambda test=test: _simulate_test(test, options.quick)))
        if solver:
            tasks.append((f"solver steps {test}",
                          lambda test=test: solver_step_statistics(canonical_scenario(test, False))))
    # the sweeps (small results, most of a first run's compiling) run in a process of their own
    # from the start, beside the tests; with processes=0 here, last, as before
    with ForkedCall(functools.partial(simulate_gain_effects, options.quick), options.processes,
                    "gain-sweeps") as sweeps:
        tasks.append(("gain sweeps", sweeps.result))
        outputs = {}
        with options.progress_for("study leader", len(tasks)) as progress:
            for label, task in tasks:
                progress.start(label)
                outputs[label] = task()
                progress.done()
    runs = {test: outputs[f"simulate {test}"] for test in EXAMPLES}
    solver_runs = {test: outputs.get(f"solver steps {test}") for test in EXAMPLES}
    effects = outputs["gain sweeps"]
    return LeaderStudyResult(runs, solver_runs, effects, options.quick, time.perf_counter() - started)


# ---------------------------------------------------------------------------------- results

class LeaderStudyResult(StudyResult):
    """The leader study's data (``cells``, ``runs``, ``solver_runs``, ``effects``), its
    generated ``findings`` and its presentations (text, HTML, CSV/JSON, figures)."""

    name = "leader"
    title = "Leader robot: thesis Chapter 5 reproduced (Tables 5.2–5.6)"

    def __init__(self, runs: dict, solver_runs: dict[str, SolverStepResult | None], effects: list[GainEffect],
                 quick: bool, elapsed_s: float):
        self.runs = runs
        self.solver_runs = solver_runs
        self.effects = effects
        self.quick = quick
        self.elapsed_s = elapsed_s
        self.cells = {(test, c): self._cell(test, c) for test in EXAMPLES for c in CONTROLLERS}
        self.findings = derive_findings(self)

    def _cell(self, test: str, controller: str) -> Cell:
        summary = self.runs[test].to_dict()["robots"][controller]
        solver = self.solver_runs[test]
        return Cell(test, controller, _statistics(summary), _statistics(solver.robot(controller)) if solver else None,
                    dict(thesis.ERROR_STATISTICS[test][controller]) if controller in thesis.THESIS_CONTROLLERS
                    else None)

    @property
    def has_solver(self) -> bool:
        return all(r is not None for r in self.solver_runs.values())

    # -- derived numbers
    def ranks(self, test: str, source: str) -> dict[str, int]:
        """Rank (1 = lowest mean error) of the five thesis controllers by ``source``:
        "uniform", "solver-steps" or "thesis"."""
        def mean(c):
            cell = self.cells[(test, c)]
            return {"uniform": cell.uniform, "solver-steps": cell.solver, "thesis": cell.thesis}[source]["mean"]
        order = sorted(thesis.THESIS_CONTROLLERS, key=mean)
        return {c: order.index(c) + 1 for c in thesis.THESIS_CONTROLLERS}

    def score(self, statistic: str, sampling: str) -> float:
        """Spec §5.3's agreement score: mean over the 20 cells of |ln(ours/thesis)|."""
        return agreement_score(((c.uniform if sampling == "uniform" else c.solver)[statistic], c.thesis[statistic])
                               for c in self.cells.values() if c.thesis)

    def convergence_time(self, test: str, controller: str) -> float | None:
        """First time after which the error stays below ``CONVERGED`` (None if never)."""
        run = self.runs[test]
        error = run.error_norm()[run.index(controller)]
        above = np.flatnonzero(error >= CONVERGED)
        if above.size == 0:
            return 0.0
        return None if above[-1] == error.size - 1 else float(run.t[above[-1] + 1])

    # -- presentations
    def table_rows(self, test: str) -> list[list[str]]:
        ours_rank = self.ranks(test, "uniform")
        thesis_rank = self.ranks(test, "thesis")
        solver_rank = self.ranks(test, "solver-steps") if self.has_solver else {}
        rows = []
        for c in CONTROLLERS:
            cell = self.cells[(test, c)]
            row = [LABELS[c], fmt(cell.uniform["mean"]), fmt(cell.uniform["std"]), fmt(cell.uniform["var"]),
                   fmt(cell.uniform["final"]), str(ours_rank.get(c, "–"))]
            row += ([fmt(cell.thesis[s]) for s in thesis.STATISTICS] + [str(thesis_rank[c]), f"{cell.ratio():.3g}"]
                    if cell.thesis else ["–"] * 5)
            if self.has_solver:
                row += [fmt(cell.solver["mean"]), fmt(cell.solver["std"]), str(solver_rank.get(c, "–")),
                        f"{cell.ratio('mean', 'solver'):.3g}" if cell.thesis else "–"]
            rows.append(row)
        return rows

    def table_header(self) -> list[str]:
        header = ["controller", "mean", "std", "var", "e(T)", "rank", "mean", "std", "var", "rank", "ours/ thesis"]
        if self.has_solver:
            header += ["mean", "std", "rank", "mean/ thesis"]
        return header

    def table_groups(self) -> list[tuple[str, int]]:
        groups = [("", 1), ("ours, uniform grid", 5), ("thesis", 4), ("mean", 1)]
        return groups + ([("ours, over solver steps", 4)] if self.has_solver else [])

    def table_caption(self, test: str) -> str:
        steps = self.runs[test].scenario.n_steps
        return (f"{TEST_TITLES[test]} (thesis {thesis.TABLE_OF_TEST[test]}): error norm in m, var in m²; ours on the "
                f"uniform grid (N = {steps}), ranks among the five thesis controllers by mean")

    def summary_rows(self, test: str) -> list[list[str]]:
        """The terminal's per-test table: ours, the thesis's mean, the ratio, ranks, solver steps."""
        ours_rank, thesis_rank = self.ranks(test, "uniform"), self.ranks(test, "thesis")
        rows = []
        for c in CONTROLLERS:
            cell = self.cells[(test, c)]
            rank = f"{ours_rank[c]} ({thesis_rank[c]})" if c in thesis_rank else "–"
            row = [LABELS[c], fmt(cell.uniform["mean"]), fmt(cell.uniform["std"]), fmt(cell.uniform["final"]),
                   fmt(cell.thesis["mean"]) if cell.thesis else "–", f"{cell.ratio():.3g}" if cell.thesis else "–",
                   rank]
            if self.has_solver:
                row += [fmt(cell.solver["mean"]), f"{cell.ratio('mean', 'solver'):.3g}" if cell.thesis else "–"]
            rows.append(row)
        return rows

    def summary_header(self) -> list[str]:
        header = ["controller", "mean", "std", "e(T)", "thesis", "ratio", "rank"]
        return header + (["solver", "ratio"] if self.has_solver else [])

    def text(self, width: int = TERMINAL_WIDTH) -> str:
        """A summary for the terminal (the full tables are in the report and its CSV)."""
        lines = [self.title, "", wrap("Error norm ‖p_d − p‖ in m. mean, std, e(T): ours on the uniform grid; "
                                      "thesis: its mean (Tables 5.2–5.5); ratio: ours/thesis; rank: ours (thesis) "
                                      "among the five thesis controllers"
                                      + ("; solver: our mean over the accepted steps of a Simulink-like "
                                         "variable-step solver, and its ratio to the thesis." if self.has_solver
                                         else ".")
                                      + (" QUICK MODE: not the canonical numbers." if self.quick else ""), width), ""]
        for test in EXAMPLES:
            lines += [f"{TEST_TITLES[test]} (thesis {thesis.TABLE_OF_TEST[test]})",
                      fitted_table(self.summary_header(), self.summary_rows(test), width), ""]
        lines += ["Table 5.6 (Test 1 sweeps): how the mean error moves as each gain increases",
                  fitted_table(["controller", "gain", "ours", "thesis", "agrees"],
                               [[r[0], r[1], r[3], e.claim, r[5]] for r, e in zip(self.effect_rows(), self.effects)],
                               width, ["range"]), ""]
        lines += ["Differences from the thesis (the reasons, with citations, are in the report):",
                  findings_text([dataclasses.replace(f, reason="") for f in self.findings], width)]
        return "\n".join(lines)

    def effect_rows(self) -> list[list[str]]:
        return [[LABELS[e.controller], e.gain, f"{e.sweep.axes[0].values[0]:g}…{e.sweep.axes[0].values[-1]:g}",
                 e.trend.word, e.claim_text, "yes" if e.agrees else "no"] for e in self.effects]

    def html_section(self, folder: Path, draw: Callable = draw_now) -> str:
        from nonholo.studies.plots import plot_comparison, plot_sweep_panels, plot_test, plot_test_inputs

        parts = [f"<p>{escape(_setup_text(self))}</p>", '<h2 id="leader-differences">Differences from the thesis</h2>',
                 html_list(f.html() for f in self.findings),
                 '<h2 id="leader-tables">Tables 5.2–5.5, ours beside the thesis</h2>']
        series = {"ours (uniform grid)": self._means("uniform")}
        if self.has_solver:
            series["ours (solver steps)"] = self._means("solver")
        series["thesis"] = self._means("thesis")
        for test in EXAMPLES:
            parts.append(html_table(self.table_header(), self.table_rows(test), self.table_caption(test),
                                    self.table_groups()))
        draw(plot_comparison, list(EXAMPLES), CONTROLLERS, LABELS, series, folder / "comparison.png")
        parts.append(html_figure(f"{folder.name}/comparison.png", "Mean error per test and controller, log scale "
                                 "(offset point has no thesis value)."))
        for test in EXAMPLES:
            parts.append(f'<h2 id="leader-{test.lower()}">{escape(TEST_TITLES[test])}</h2>')
            name = f"{test.lower()}.png"
            draw(plot_test, self.runs[test], TEST_TITLES[test], LABELS, folder / name, PATH_WINDOW[test])
            parts.append(html_figure(f"{folder.name}/{name}", f"{TEST_TITLES[test]} (thesis Figures 5.5–5.24): "
                                     "every controller from the origin with θ(0) = 0. Where two controllers' lines "
                                     "coincide, the thinner one is drawn inside the wider one."))
            name = f"{test.lower()}-inputs.png"
            draw(plot_test_inputs, self.runs[test], TEST_TITLES[test], LABELS, folder / name, INPUT_WINDOW[test])
            parts.append(html_figure(f"{folder.name}/{name}", f"{TEST_TITLES[test]}: the applied driving speed v and "
                                     "turn rate ω of each controller beside the reference's v_d and ω_d (dashed), and "
                                     "its heading error e3 = θ_d − θ wrapped to (−180°, 180°]. Each column shares its "
                                     "scale; a start-up peak outside it is clipped and named above its panel."))
        parts.append('<h2 id="leader-sweeps">Table 5.6: gain sweeps on Test 1 (Figures 5.25–5.38)</h2>')
        parts.append(html_table(["controller", "gain", "range", "ours", "thesis", "agrees"], self.effect_rows(),
                                "Effect of increasing the gain on the mean error (others at Table 5.1 values)"))
        parts.append(f"<p class=\"note\">{escape(_trend_rule())}</p>")
        for controller in thesis.THESIS_CONTROLLERS:
            effects = [e for e in self.effects if e.controller == controller]
            name = f"sweep-{controller}.png"
            draw(plot_sweep_panels, effects, f"Test 1, {LABELS[controller]}: mean error against each gain",
                 folder / name)
            parts.append(html_figure(f"{folder.name}/{name}", f"{LABELS[controller]}: dotted line = Table 5.1 value."))
        return "\n".join(parts)

    def _means(self, source: str) -> dict:
        out = {}
        for test in EXAMPLES:
            values = {}
            for c in CONTROLLERS:
                cell = self.cells[(test, c)]
                chosen = {"uniform": cell.uniform, "solver": cell.solver, "thesis": cell.thesis}[source]
                values[c] = chosen["mean"] if chosen else None
            out[test] = values
        return out

    def to_dict(self) -> dict:
        return {
            "study": self.name, "quick": self.quick, "elapsed_s": self.elapsed_s,
            "setup": _setup_text(self),
            "solver_settings": next((r.settings.describe() for r in self.solver_runs.values() if r), None),
            "cells": [{"test": c.test, "controller": c.controller, "uniform": c.uniform, "solver_steps": c.solver,
                       "thesis": c.thesis} for c in self.cells.values()],
            "ranks": {test: {s: self.ranks(test, s) for s in ("uniform", "thesis")
                             + (("solver-steps",) if self.has_solver else ())} for test in EXAMPLES},
            "scores": self.scores(),
            "gain_effects": [{"controller": e.controller, "gain": e.gain, "thesis": e.claim, "ours": e.trend.word,
                              "agrees": e.agrees, "sweep": e.sweep.to_dict()} for e in self.effects],
            "findings": [dataclasses.asdict(f) for f in self.findings],
            "runs": {test: run.to_dict() for test, run in self.runs.items()},
        }

    def scores(self) -> dict:
        samplings = ("uniform", "solver") if self.has_solver else ("uniform",)
        return {s: {stat: self.score(stat, s) for stat in ("mean", "std")} for s in samplings}

    def write_data(self, folder: Path) -> list[Path]:
        table = folder / "leader-tables.csv"
        with open(table, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["test", "controller", "sampling", "mean", "std", "var", "rms", "max", "final"])
            for cell in self.cells.values():
                for sampling, stats in (("uniform", cell.uniform), ("solver-steps", cell.solver),
                                        ("thesis", cell.thesis)):
                    if stats:
                        writer.writerow([cell.test, cell.controller, sampling,
                                         *(f"{stats[k]:.10g}" if k in stats else "" for k in
                                           ("mean", "std", "var", "rms", "max", "final"))])
        sweeps = folder / "leader-sweeps.csv"
        with open(sweeps, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["controller", "gain", "value", "error_mean", "error_std", "error_rms", "error_max",
                             "error_final"])
            for e in self.effects:
                for row in e.sweep.rows():
                    writer.writerow([e.controller, e.gain, *(f"{v:.10g}" for v in row)])
        data = folder / "leader.json"
        data.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False))
        return [table, sweeps, data]


def _trend_rule() -> str:
    from nonholo.studies.sweep import FLAT_FRACTION, SIGNIFICANT_STEP_FRACTION

    return (f"Classification: steps between neighbouring grid points smaller than {SIGNIFICANT_STEP_FRACTION:.0%} of "
            f"the mean error's range over the sweep are ignored; the remaining steps form monotone runs: one run = "
            f"decreases/increases, two = \"X, then Y\", three or more = oscillates; a range below "
            f"{FLAT_FRACTION:.1%} of the largest value = no effect. The thesis's sweep ranges are not known "
            f"(its figures are not in the text); ours are listed in the table.")


def _setup_text(result: LeaderStudyResult) -> str:
    steps = ", ".join(f"{t}: N = {r.scenario.n_steps}, T = {r.t[-1]:.5g} s" for t, r in result.runs.items())
    solver = next((r.settings.describe() for r in result.solver_runs.values() if r), None)
    text = (f"Canonical set-up (spec leader.md §5.1): robot at the origin, θ(0) = 0, ξ(0) = v_d(0), exact "
            f"feedforward, Table 5.1 gains, RK4 ({steps}); statistics of the error norm ‖p_d − p‖ over the uniform "
            f"grid (std with ddof 0).")
    if solver:
        text += (f" Solver-step statistics: {solver['solver']}, rtol {solver['rtol']:g}, atol {solver['atol']:g}, "
                 f"h_max = T/50, sampled at every accepted step (the solver chooses its own steps, also in quick mode).")
    if result.quick:
        text += f" QUICK MODE: N = {QUICK_STEPS} steps and {QUICK_SWEEP_POINTS}-point sweeps (not the canonical numbers)."
    return text


# ---------------------------------------------------------------------------------- findings

def derive_findings(result: LeaderStudyResult) -> list[Finding]:
    """The "differences from the thesis" section, computed from the numbers."""
    findings = [_overall_agreement(result), _reproduced_cells(result), _persistent_errors(result),
                _dfl_lowest(result), _test4_failures(result)]
    if result.has_solver:
        findings.append(_test4_sampling(result))
    findings += _rank_changes(result)
    findings += _thesis_inconsistencies()
    findings.append(_gain_effect_agreement(result))
    return findings


def _overall_agreement(result: LeaderStudyResult) -> Finding:
    scores = result.scores()
    parts = [f"uniform grid: mean {scores['uniform']['mean']:.2f}, std {scores['uniform']['std']:.2f}"]
    if "solver" in scores:
        parts.append(f"solver steps: mean {scores['solver']['mean']:.2f}, std {scores['solver']['std']:.2f}")
    far = [c for c in result.cells.values() if c.thesis and log_ratio(c.uniform["mean"], c.thesis["mean"]) > FAR]
    return Finding("Overall agreement", "note",
                   f"score = mean over the 20 cells of |ln(ours/thesis)| (0 = exact, 2.3 = a factor of 10): "
                   f"{'; '.join(parts)}. {len(far)} of 20 uniform-grid means differ from the thesis by more than 10×.",
                   "exact feedforward and a documented start reproduce the thesis only where its set-up is "
                   "unambiguous; statistics over solver steps (spec §5.3) bring the score down.")


def _reproduced_cells(result: LeaderStudyResult) -> Finding:
    def close(sampling):
        return [f"{c.test} {LABELS[c.controller]} ({(c.uniform if sampling == 'uniform' else c.solver)['mean']:.3g} "
                f"vs {c.thesis['mean']:.3g} m)" for c in result.cells.values()
                if c.thesis and (sampling == "uniform" or c.solver)
                and log_ratio((c.uniform if sampling == "uniform" else c.solver)["mean"], c.thesis["mean"]) <= CLOSE]
    uniform = close("uniform")
    text = f"means within 15 % of the thesis on the uniform grid: {', '.join(uniform) or 'none'}"
    if result.has_solver:
        text += f"; over solver steps: {', '.join(close('solver')) or 'none'}"
    return Finding("Cells reproduced", "partly" if uniform else "fails", text + ".",
                   "the canonical start reproduces Test 2 DFL and Test 4 cascaded, the two cells whose set-up the "
                   "thesis pins down (spec §5.3).")


def _persistent_errors(result: LeaderStudyResult) -> Finding:
    converged = [c for c in result.cells.values() if c.test != "T4" and c.thesis
                 and c.uniform["final"] < CONVERGED and c.thesis["mean"] > 10 * c.uniform["mean"]]
    return Finding("Persistent errors in Tests 1–3", "fails" if converged else "holds",
                   f"in {len(converged)} of 15 Test 1–3 cells our error has converged (e(T) < {CONVERGED:g} m) and our "
                   f"mean is over 10× below the thesis's, e.g. "
                   + ", ".join(f"{c.test} {LABELS[c.controller]} {c.uniform['mean']:.2g} vs {c.thesis['mean']:.3g} m"
                               for c in converged[:4]) + ".",
                   "with exact feedforward e = 0 is invariant for every law, so no persistent error can arise; the "
                   "thesis's errors most likely come from numerically differentiated feedforward (Simulink Derivative "
                   "blocks: output 0 at t = 0, half-step lag; spec §5.5, erratum 19) and possibly unwrapped heading "
                   "errors (spec §5.3 variant E).")


def _dfl_lowest(result: LeaderStudyResult) -> Finding:
    tests = ("T1", "T2", "T3")
    thesis_holds = all(result.ranks(t, "thesis")["dynamic-feedback"] == 1 for t in tests)
    ours = {t: result.ranks(t, "uniform") for t in tests}
    winners = {t: min(ours[t], key=ours[t].get) for t in tests}
    holds = all(ours[t]["dynamic-feedback"] == 1 for t in tests)
    evidence = (f"thesis: DFL {'is' if thesis_holds else 'is not'} lowest in its own Tables 5.2–5.4. Ours: DFL ranks "
                + ", ".join(f"{ours[t]['dynamic-feedback']} of 5 in {t} (lowest: {LABELS[winners[t]]})" for t in tests))
    if result.has_solver:
        solver = {t: result.ranks(t, "solver-steps")["dynamic-feedback"] for t in tests}
        evidence += "; over solver steps " + ", ".join(f"{solver[t]} in {t}" for t in tests)
    t3 = result.cells[("T3", "dynamic-feedback")].uniform
    evidence += f". Its Test 3 peak error is {t3['max']:.2g} m."
    return Finding(f"Thesis §5.4: “{thesis.CONCLUSION_DFL_LOWEST}” (lowest mean error in Tests 1–3)",
                   "holds" if holds else "fails", evidence + (" Reproduced." if holds else " Not reproduced."),
                   "DFL's error dynamics are exactly linear with a soft PD loop (kp = 1, kd = 0.7: ω_n = 1 rad/s, "
                   "ζ = 0.35) that must absorb the initial velocity error |ṗ_d(0) − ξ(0)(cos θ(0), sin θ(0))| "
                   "(13.5 m/s on Test 3), while the static laws with exact feedforward converge within seconds "
                   "(spec §5.4, §3.6).")


def _test4_failures(result: LeaderStudyResult) -> Finding:
    run = result.runs["T4"]
    start_error = float(run.error_norm()[0, 0])
    verdicts = {}
    for c in thesis.THESIS_CONTROLLERS:
        final = result.cells[("T4", c)].uniform["final"]
        settle = result.convergence_time("T4", c)
        if final >= FAILED_FRACTION * start_error:
            verdicts[c] = f"fails (e(T) = {final:.3g} m of e(0) = {start_error:.3g} m)"
        elif settle is None:
            verdicts[c] = f"slow (e(T) = {final:.2g} m, never below {CONVERGED:g} m)"
        else:
            verdicts[c] = f"converges (below {CONVERGED:g} m after {settle:.3g} s)"
    cascaded_fails = verdicts["cascaded"].startswith("fails")
    kanayama_fails = verdicts["kanayama"].startswith("fails")
    others_converge = all(verdicts[c].startswith("converges")
                          for c in ("approximate-linearization", "nonlinear", "dynamic-feedback"))
    verdict = "holds" if cascaded_fails and kanayama_fails and others_converge else \
        "partly" if cascaded_fails or kanayama_fails else "fails"
    gains = run.scenario.robots[run.index("cascaded")].controller.gains
    omega_d = float(np.abs(run.omega_d).mean())
    slow_rate = (1 + gains["c3"]) * omega_d ** 2 / gains["c2"]
    kanayama = run.scenario.robots[run.index("kanayama")].controller.gains
    peak_v = float(run.metrics.peak_v[run.index("kanayama")])
    reason = (f"not the thesis's: ω_d ≡ {omega_d:.3g} rad/s is persistently exciting and ω̇_d ≡ 0 (errata 23–24). "
              f"Cascaded: with e3 = 0 the cross-track error decays only through ω_d, slow mode "
              f"−(1 + c3)ω_d²/c2 = −{slow_rate:.2g} 1/s (τ ≈ {1 / slow_rate:.0f} s ≫ T = {run.t[-1]:.0f} s): the robot "
              f"stays near the centre. Stable tracking: very soft lateral gains in SI units (Ky = {kanayama['ky']:g}, "
              f"Kθ = {kanayama['ktheta']:g}: lateral loop v_d√Ky = {0.5 * math.sqrt(kanayama['ky']):.2g} rad/s), "
              f"a local result and a {start_error:.0f} m initial error (Kx e1 commands {peak_v:.3g} m/s at t = 0).")
    return Finding(f"Thesis §5.4: “{thesis.CONCLUSION_TEST4_FAILURES}”", verdict,
                   "; ".join(f"{LABELS[c]} {v}" for c, v in verdicts.items()) + ".", reason)


def _test4_sampling(result: LeaderStudyResult) -> Finding:
    chosen = ("approximate-linearization", "nonlinear", "dynamic-feedback")
    cells = [result.cells[("T4", c)] for c in chosen]
    uniform = [c.thesis["mean"] / c.uniform["mean"] for c in cells]
    solver = [c.thesis["mean"] / c.solver["mean"] for c in cells]
    explained = max(log_ratio(1, r) for r in solver) < math.log(2) < min(log_ratio(1, r) for r in uniform)
    return Finding("Test 4 magnitudes and the sampling of the statistics", "holds" if explained else "partly",
                   "thesis mean / our mean for approx. lin., nonlinear, DFL on Test 4: uniform grid "
                   + ", ".join(f"{r:.2g}×" for r in uniform) + "; over solver steps "
                   + ", ".join(f"{r:.2g}×" for r in solver)
                   + (". Solver-step statistics explain the magnitudes (within 2×)." if explained else "."),
                   "Simulink logs its variable steps, dense in the initial 10 m transient and sparse afterwards, "
                   "so averages over them weight the transient heavily (spec §5.3, §5.5 item 1).")


def _rank_changes(result: LeaderStudyResult) -> list[Finding]:
    findings = []
    for test in EXAMPLES:
        thesis_order = sorted(thesis.THESIS_CONTROLLERS, key=result.ranks(test, "thesis").get)
        ours = result.ranks(test, "uniform")
        ours_order = sorted(thesis.THESIS_CONTROLLERS, key=ours.get)
        moved = [c for c in thesis.THESIS_CONTROLLERS if ours[c] != result.ranks(test, "thesis")[c]]
        findings.append(Finding(
            f"Ranking by mean error, {test}", "holds" if not moved else "partly" if len(moved) <= 2 else "fails",
            f"thesis {' < '.join(LABELS[c] for c in thesis_order)}; ours {' < '.join(LABELS[c] for c in ours_order)}"
            + (f" ({len(moved)} of 5 controllers change rank)." if moved else " (same order).")))
    return findings


def _decimals(value: float) -> int:
    text = repr(value)
    return len(text.split(".")[1]) if "." in text and "e" not in text else 4


def _thesis_inconsistencies() -> list[Finding]:
    """Rows whose printed std² cannot equal the printed variance (rounding allowed for)."""
    findings = []
    for test in thesis.TESTS:
        for controller, row in thesis.ERROR_STATISTICS[test].items():
            std, var = row["std"], row["var"]
            d_std, d_var = 0.5 * 10 ** -_decimals(std), 0.5 * 10 ** -_decimals(var)
            low, high = (std - d_std) ** 2, (std + d_std) ** 2
            if high < var - d_var or low > var + d_var:
                findings.append(Finding(
                    f"Thesis {thesis.TABLE_OF_TEST[test]}, {LABELS[controller]}", "note",
                    f"printed std {std:g} m gives std² = {std * std:.5g} m², printed var is {var:g} "
                    f"(√var = {math.sqrt(var):.5g} m): the row is internally inconsistent.",
                    "a typo in the thesis (spec errata 20–21); var is in m², not m."))
    return findings


def _gain_effect_agreement(result: LeaderStudyResult) -> Finding:
    agree = [e for e in result.effects if e.agrees]
    return Finding("Table 5.6 (gain effects on Test 1)", "holds" if len(agree) == len(result.effects)
                   else "partly" if agree else "fails",
                   f"{len(agree)} of {len(result.effects)} thesis claims agree with the trend of our sweeps"
                   + (": " + ", ".join(f"{LABELS[e.controller]} {e.gain}" for e in agree) if agree else "")
                   + ". Disagreements: " + ", ".join(f"{LABELS[e.controller]} {e.gain} (ours {e.trend.word}, "
                                                     f"thesis {e.claim})" for e in result.effects if not e.agrees)
                   + ".",
                   "our mean errors on Test 1 are set by the initial transient from the origin with θ(0) = 0 and "
                   "exact feedforward; the thesis's by its persistent errors (see above), so gains act differently.")


STUDY = Study(
    name="leader", title=LeaderStudyResult.title,
    summary="Tests 1-4 x five thesis controllers (+ offset point), Tables 5.2-5.6 beside the thesis, gain sweeps",
    run=run_leader,
    order=1,
)
