"""Gain tuning: scipy's ``differential_evolution`` over some gains of one robot, each
generation's whole population simulated as one batch (``vectorized=True``), optionally
robust over a Monte-Carlo set of starts (the objective averaged over them).

>>> Objective.parse("rms + 0.01*effort + 10*saturation").terms
(('rms', 1.0), ('effort', 0.01), ('saturation', 10.0))

**Objective terms** (of the tuned robot, per run): ``mean``, ``rms``, ``max``, ``final`` of
the error norm (m); ``ise`` = ∫|e|² dt ≈ duration · rms² (m²·s); ``effort`` = ∫(v² + ω²) dt;
``saturation``: the share of samples at which a limit clipped a command; ``heading``: the
heading error's rms. A diverged run scores ``DIVERGED_PENALTY``.

Closed-form check (tests): dynamic feedback on a straight line from a start on the line
with a speed error has linear error dynamics ë + kd ė + kp e = 0 per axis, so
∫|e|² dt = |ė(0)|² / (2 kp kd): over bounds, the optimum is the largest kp and kd.
"""
from __future__ import annotations

import dataclasses
import math
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from nonholo.errors import NonholoInputError
from nonholo.sim.result import Metrics
from nonholo.sim.scenario import Follower
from nonholo.sim.simulator import diverged, simulate
from nonholo.studies import distributed
from nonholo.studies.montecarlo import Variation, draw, sample_scenario, varied_part
from nonholo.studies.sweep import choose_robot, sweepable

TERMS = ("mean", "rms", "max", "final", "ise", "effort", "saturation", "heading")
DIVERGED_PENALTY = 1e12
_TERM = re.compile(r"^\s*(?:([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*\*\s*)?([a-z]+)\s*$")


@dataclass(frozen=True)
class Objective:
    """A weighted sum of metric terms, ``W*NAME + …`` (parsed, never evaluated)."""

    terms: tuple[tuple[str, float], ...]

    @classmethod
    def parse(cls, text: str) -> "Objective":
        terms = []
        for part in text.split("+"):
            match = _TERM.match(part)
            if not match or match.group(2) not in TERMS:
                raise NonholoInputError(f"--objective {text!r}: each term is [WEIGHT*]NAME with NAME one of "
                                        f"{', '.join(TERMS)}"[:300])
            weight = float(match.group(1)) if match.group(1) else 1.0
            if not (math.isfinite(weight) and weight >= 0):
                raise NonholoInputError(f"--objective {text!r}: weights must be finite and >= 0")
            terms.append((match.group(2), weight))
        return cls(tuple(terms))

    def describe(self) -> str:
        return " + ".join(name if w == 1.0 else f"{w:g}*{name}" for name, w in self.terms)

    def values(self, stats: np.ndarray, samples: int, duration: float) -> np.ndarray:
        """The objective per member of a robot's statistics (STAT_COUNT, members)."""
        m = Metrics.from_stats(stats, samples, duration)
        saturation = m.saturated / samples
        term = {"mean": m.error_mean, "rms": m.error_rms, "max": m.error_max, "final": m.error_final,
                "ise": duration * m.error_rms ** 2, "effort": m.effort, "saturation": saturation,
                "heading": m.heading_rms}
        total = sum(w * term[name] for name, w in self.terms)
        bad = diverged(stats[:, None, :])[0] | ~np.isfinite(total)
        return np.where(bad, DIVERGED_PENALTY, total)


@dataclass(frozen=True)
class Bound:
    name: str
    low: float
    high: float

    @classmethod
    def parse(cls, text: str) -> "Bound":
        """``NAME=LOW:HIGH``."""
        name, sep, spec = text.partition("=")
        low, colon, high = spec.partition(":")
        try:
            bound = cls(name.strip(), float(low), float(high))
        except ValueError:
            bound = None
        if not sep or not colon or bound is None or not name.strip():
            raise NonholoInputError(f"--bounds must look like NAME=LOW:HIGH, got {text!r}"[:200])
        if not (math.isfinite(bound.low) and math.isfinite(bound.high) and bound.low < bound.high):
            raise NonholoInputError(f"--bounds {text!r}: need finite LOW < HIGH")
        return bound


def evaluate_chunk(payload: dict) -> np.ndarray:
    """The objective of each member of a chunk (a worker's unit): ``payload`` has the TOML
    ``text``, ``source``, ``steps``, the tuned ``robot``, the ``fields`` and ``values`` per
    member (chunk, fields), and the ``objective`` text."""
    base = distributed.scenario_of(payload["text"], payload["source"])
    if payload["steps"] is not None:
        base = dataclasses.replace(base, dt=None, steps=payload["steps"])
    part = varied_part(base, [payload["robot"]])
    members = [sample_scenario(part, payload["fields"], row) for row in payload["values"]]
    result = simulate(members, record=False, progress=False, on_divergence="report")
    index = part.names.index(payload["robot"])
    return Objective.parse(payload["objective"]).values(result.stats[:, index, :], result.t.size,
                                                         float(result.t[-1]))


@dataclass
class TuneResult:
    """The optimum ``gains`` and its ``objective``; ``baseline`` the thesis's Table 5.1 gains
    (the law's defaults; a follower's scenario values) and their objective; the best
    objective after each generation in ``history``."""

    scenario: str
    robot: str
    controller: str
    objective_text: str
    bounds: tuple[Bound, ...]
    gains: dict
    objective: float
    baseline: dict
    baseline_objective: float
    metrics: dict
    baseline_metrics: dict
    history: list
    evaluations: int
    generations: int
    starts: int
    seed: int
    timing: dict = field(default_factory=dict)

    def bound_warning(self, share: float = 0.01) -> str | None:
        """A one-line warning if the optimum lies on a bound (within ``share`` of its range),
        else None: the optimum may lie beyond it."""
        parts = []
        for bound in self.bounds:
            value, span = self.gains.get(bound.name), bound.high - bound.low
            if value is None or span <= 0:
                continue
            for side, edge in (("lower", bound.low), ("upper", bound.high)):
                if abs(value - edge) <= share * span:
                    parts.append(f"{bound.name} = {value:.4g} is at its {side} bound ({bound.low:g}:{bound.high:g})")
        if not parts:
            return None
        return f"warning: {'; '.join(parts)}: the optimum may lie beyond it; widen --bounds that way"

    def to_dict(self) -> dict:
        """JSON-ready; apart from ``timing`` it depends only on the scenario, options and seed."""
        return {"scenario": self.scenario, "robot": self.robot, "controller": self.controller,
                "objective": self.objective_text, "bounds": {b.name: [b.low, b.high] for b in self.bounds},
                "seed": self.seed, "starts": self.starts,
                "optimum": {"gains": self.gains, "objective": self.objective, "metrics": self.metrics},
                "baseline": {"gains": self.baseline, "objective": self.baseline_objective,
                             "metrics": self.baseline_metrics},
                "generations": self.generations, "evaluations": self.evaluations, "history": self.history,
                "timing": self.timing}

    def plot(self, path=None):
        """Convergence: the best objective after each generation (log scale), the baseline's
        objective as a line."""
        import matplotlib

        if path is not None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.4, 3.6))
        ax.plot(range(1, len(self.history) + 1), self.history, marker="o", markersize=3, label="best of population")
        ax.axhline(self.baseline_objective, color="#c0392b", linestyle="--", linewidth=1,
                   label="Table 5.1 gains " + ", ".join(f"{k} = {v:g}" for k, v in self.baseline.items()))
        if min(self.history + [self.baseline_objective]) > 0:
            ax.set_yscale("log")
        ax.set_xlabel("generation")
        ax.set_ylabel(self.objective_text)
        ax.set_title(f"{self.scenario}, {self.robot}: tuning " + ", ".join(self.gains), fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=110)
            plt.close(fig)
        return fig


def run_tune(text: str, gains: Sequence[str], bounds: Sequence[str] = (), objective: str = "rms",
             source: str = "<scenario>", robot: str | None = None, steps: int | None = None,
             starts: Sequence[str] = (), start_samples: int = 0, seed: int = 0, maxiter: int = 30,
             popsize: int = 10, tol: float = 1e-6, dask: str | None = None, progress: bool | None = None) -> TuneResult:
    """Tune ``gains`` of one robot of the scenario of TOML ``text`` by differential
    evolution (seeded; no polishing, so every evaluation is a batch). ``bounds``:
    ``NAME=LOW:HIGH`` (default: a tenth to ten times the scenario's value). ``starts``:
    variations (``ROBOT.start.x=normal(0, 0.5)``, any ``--vary`` field) drawn
    ``start_samples`` times: the objective is then the mean over that Monte-Carlo set."""
    from scipy.optimize import differential_evolution

    started = time.perf_counter()
    distributed.check_address(dask)
    goal = Objective.parse(objective)
    scenario = distributed.scenario_of(text, source)
    if steps is not None:
        if steps < 1:
            raise NonholoInputError(f"--steps must be a positive integer, got {steps}")
        scenario = dataclasses.replace(scenario, dt=None, steps=steps)
    gains = [g.strip() for g in gains if g.strip()]
    if not gains or len(set(gains)) != len(gains):
        raise NonholoInputError("--gains: give distinct gain names, e.g. kp,kd")
    target = choose_robot(scenario, gains, robot)
    for gain in gains:
        if gain not in sweepable(target):
            raise NonholoInputError(f"--gains {gain}: not a gain of {target.name} (gains: "
                                    f"{', '.join(sweepable(target))})"[:300])
    paths = [_path(target, g) for g in gains]
    current = {g: _current(target, g) for g in gains}
    baseline = {g: _thesis(target, g, current[g]) for g in gains}
    given = {b.name: b for b in (Bound.parse(t) for t in bounds)}
    unknown = sorted(set(given) - set(gains))
    if unknown:
        raise NonholoInputError(f"--bounds {unknown[0]}: not among the tuned gains ({', '.join(gains)})")
    box = []
    for g in gains:
        if g in given:
            box.append(given[g])
        elif current[g] > 0:
            box.append(Bound(g, current[g] / 10, current[g] * 10))
        else:
            raise NonholoInputError(f"--bounds: give {g}=LOW:HIGH (its value {current[g]:g} gives no default)")
    variations = tuple(Variation.parse(v, scenario) for v in starts)
    if variations and start_samples < 1:
        raise NonholoInputError("--start-samples must be >= 1 with --start")
    if any(v.robot == target.name and v.path in paths for v in variations):
        raise NonholoInputError("--start: a tuned gain cannot also be varied")
    start_values = draw(variations, start_samples, seed) if variations else np.zeros((1, 0))
    part = varied_part(scenario, [target.name] + [v.robot for v in variations])
    for bound, path in zip(box, paths):   # both ends must be gains the law takes (its rules, one line)
        for value in (bound.low, bound.high):
            try:
                sample_scenario(part, [(target.name, path)], [value])
            except NonholoInputError as exc:
                raise NonholoInputError(f"--bounds {bound.name}={bound.low:g}:{bound.high:g}: {exc}") from None
    fields = [(target.name, p) for p in paths] + [(v.robot, v.path) for v in variations]
    sample_scenario(part, fields, [*baseline.values(), *(start_values[0] if variations else [])])
    n_starts = start_values.shape[0]
    work = len(part.robots) * part.n_steps * (part.substeps or 1)
    payload_base = {"text": text, "source": source, "steps": steps, "robot": target.name, "fields": fields,
                    "objective": goal.describe()}
    evaluations = 0
    history: list[float] = []
    refused: list[NonholoInputError] = []   # a gain inside the bounds that the law refuses

    def batch(points: np.ndarray, client) -> np.ndarray:
        """Objective of each row of ``points`` (members, gains), averaged over the starts."""
        nonlocal evaluations
        rows = np.column_stack([np.repeat(points, n_starts, axis=0), np.tile(start_values, (points.shape[0], 1))])
        bounds_ = distributed.chunk_bounds(rows.shape[0], work)
        out = np.empty(rows.shape[0])
        payloads = [{**payload_base, "values": rows[a:b]} for a, b in bounds_]
        try:
            for index, values in distributed.run_chunks(evaluate_chunk, payloads, client):
                a, b = bounds_[index]
                out[a:b] = values
        except NonholoInputError as exc:
            refused.append(exc)
            raise
        evaluations += points.shape[0]
        return out.reshape(points.shape[0], n_starts).mean(axis=1)

    with distributed.dask_client(dask) as client, \
            distributed.progress_bar(maxiter, "generation", f"{scenario.name}: tuning", progress) as bar:
        def callback(intermediate_result):
            history.append(float(intermediate_result.fun))
            bar.update(1)

        try:
            solution = differential_evolution(lambda x: batch(np.atleast_2d(x.T), client),
                                              [(b.low, b.high) for b in box], vectorized=True, updating="deferred",
                                              seed=seed, maxiter=maxiter, popsize=popsize, tol=tol, polish=False,
                                              callback=callback)
        except Exception:
            if refused:   # scipy wraps what the objective raises
                raise NonholoInputError(f"--bounds: {refused[0]}") from None
            raise
        best = {g: float(v) for g, v in zip(gains, np.atleast_1d(solution.x))}
        both = batch(np.array([list(best.values()), list(baseline.values())]), client)
        metrics = _metrics(part, fields, [list(best.values()), list(baseline.values())], start_values, target.name)
    return TuneResult(scenario.name, target.name, _law(target), goal.describe(), tuple(box), best, float(both[0]),
                      baseline, float(both[1]), metrics[0], metrics[1], history, evaluations, int(solution.nit),
                      n_starts, seed, {"total_s": time.perf_counter() - started, "dask": dask is not None})


def _metrics(part, fields, points, start_values, robot: str) -> list[dict]:
    """Error metrics (mean over the starts) of the tuned robot at each point."""
    n_starts = start_values.shape[0]
    members = [sample_scenario(part, fields, [*point, *start]) for point in points for start in start_values]
    result = simulate(members, record=False, progress=False, on_divergence="report")
    index = part.names.index(robot)
    m = Metrics.from_stats(result.stats[:, index, :], result.t.size, float(result.t[-1]))
    out = []
    for k in range(len(points)):
        span = slice(k * n_starts, (k + 1) * n_starts)
        out.append({name: float(np.mean(getattr(m, attribute)[span])) for name, attribute in
                    (("error_mean", "error_mean"), ("error_rms", "error_rms"), ("error_max", "error_max"),
                     ("effort", "effort"), ("peak_omega", "peak_omega"))})
    return out


def _path(robot, gain: str) -> str:
    if isinstance(robot, Follower) and gain in ("d", *robot.outputs):
        return gain
    return f"gains.{gain}"


def _current(robot, gain: str) -> float:
    if isinstance(robot, Follower):
        if gain in robot.outputs:
            return float(robot.targets[robot.outputs.index(gain)])
        return float(getattr(robot, gain))
    config = robot.controller
    if gain in config.gains:
        return float(config.gains[gain])
    if gain == config.controller.initial_gain and config.xi0 is not None:
        return float(config.xi0)
    targets = config.controller.aliases.get(gain, ())
    if targets:
        return float(config.gains[targets[0]])
    raise NonholoInputError(f"--gains {gain}: {robot.name} has no value for it; give --bounds {gain}=LOW:HIGH")


def _thesis(robot, gain: str, current: float) -> float:
    """The thesis's Table 5.1 value of a root law's gain (the registry's default), else the
    scenario's value (followers; gains without a default)."""
    if isinstance(robot, Follower):
        return current
    spec = robot.controller.controller
    name = spec.aliases.get(gain, (gain,))[0]
    value = spec.defaults.get(name)
    return float(value) if value is not None and math.isfinite(value) else current


def _law(robot) -> str:
    return robot.law if isinstance(robot, Follower) else robot.controller.name
