"""Gain sweeps: one or two gains of one robot varied over a grid, simulated as one batch
(one ``Scenario`` with a robot per grid point, statistics only), and the trend of a metric
along a one-gain sweep.

>>> axis = GainAxis.parse("b=0.5:2:4")
>>> axis.name, axis.values.tolist()
('b', [0.5, 1.0, 1.5, 2.0])
>>> classify_trend([3.0, 2.0, 1.5, 1.49999, 1.0]).word
'decreases'
>>> classify_trend([1.0, 2.0, 1.0, 2.0]).word
'oscillates'
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nonholo import Follower, Robot, Scenario, simulate
from nonholo.errors import NonholoInputError
from nonholo.sim.scenario import SECOND_OUTPUT_PARAMETERS
from nonholo.studies import distributed

METRICS = ("mean", "rms", "max", "final")

# A grid axis beyond this is a typo, not a study: 10⁵ × 10⁵ robots would never finish.
MAX_AXIS_POINTS = 100_000
# Trend classification (see classify_trend): a step between neighbouring grid points counts
# only if it exceeds this fraction of the metric's range over the sweep, and a metric that
# varies by less than FLAT_FRACTION of its largest value has "no effect".
SIGNIFICANT_STEP_FRACTION = 0.01
FLAT_FRACTION = 1e-3
TREND_WORDS = ("decreases", "increases", "decreases, then increases", "increases, then decreases", "oscillates",
               "increases, then oscillates", "decreases, then oscillates", "no effect")


@dataclass(frozen=True)
class GainAxis:
    """One swept gain: its name and the grid of values (linearly spaced)."""

    name: str
    values: np.ndarray

    @classmethod
    def linear(cls, name: str, start: float, stop: float, count: int) -> "GainAxis":
        if not 1 <= count <= MAX_AXIS_POINTS:
            raise NonholoInputError(f"gain {name!r}: COUNT must be from 1 to {MAX_AXIS_POINTS}, got {count}")
        if not (math.isfinite(start) and math.isfinite(stop)):
            raise NonholoInputError(f"gain {name!r}: START and STOP must be finite numbers")
        return cls(name, np.linspace(start, stop, count))

    @classmethod
    def parse(cls, text: str) -> "GainAxis":
        """``NAME=START:STOP:COUNT`` (COUNT values from START to STOP inclusive)."""
        name, sep, spec = text.partition("=")
        parts = spec.split(":")
        if not sep or not name.strip() or len(parts) != 3:
            raise NonholoInputError(f"--gain must look like NAME=START:STOP:COUNT, got {text!r}")
        try:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise NonholoInputError(f"--gain {text!r}: START and STOP must be numbers and COUNT an integer") from None
        return cls.linear(name.strip(), start, stop, count)


@dataclass(frozen=True)
class Trend:
    """How a metric moves as the gain increases.

    ``runs``: the directions ("increases"/"decreases") of the maximal monotone stretches
    of the significant steps, in order; ``word``: one of ``TREND_WORDS``.
    """

    runs: tuple[str, ...]
    word: str

    def agrees_with(self, claim: str) -> bool:
        """Whether a claim in ``TREND_WORDS`` describes this trend. "oscillates" means at
        least three monotone stretches; "X, then oscillates" also requires the first to be X."""
        if claim == "oscillates":
            return len(self.runs) >= 3
        if claim.endswith(", then oscillates"):
            return len(self.runs) >= 3 and self.runs[0] == claim.split(",")[0]
        return claim == self.word


def classify_trend(values: Sequence[float]) -> Trend:
    """Classify a metric along increasing gain values.

    Let R = max − min of the values. If R ≤ FLAT_FRACTION·max|value| the gain has "no
    effect". Otherwise the steps between neighbouring grid points with |step| >
    SIGNIFICANT_STEP_FRACTION·R are kept (smaller wiggles are ignored), consecutive steps of
    the same sign are merged into runs, and: one run → "decreases"/"increases"; two runs →
    "X, then Y"; three or more → "oscillates".
    """
    values = np.asarray(values, dtype=float)
    spread = float(values.max() - values.min()) if values.size else 0.0
    if values.size < 2 or spread <= FLAT_FRACTION * float(np.abs(values).max()):
        return Trend((), "no effect")
    steps = np.diff(values)
    signs = np.sign(steps[np.abs(steps) > SIGNIFICANT_STEP_FRACTION * spread])
    runs: list[str] = []
    for sign in signs:
        direction = "increases" if sign > 0 else "decreases"
        if not runs or runs[-1] != direction:
            runs.append(direction)
    if len(runs) == 1:
        word = runs[0]
    elif len(runs) == 2:
        word = f"{runs[0]}, then {runs[1]}"
    else:
        word = "oscillates"
    return Trend(tuple(runs), word)


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep: ``errors[statistic]`` has the grid's shape (len(axes[0]) [×
    len(axes[1])]) for statistic in mean, std, rms, max, final; ``values`` is the chosen
    ``metric``."""

    scenario: str
    robot: str
    controller: str
    axes: tuple[GainAxis, ...]
    metric: str
    errors: dict
    elapsed_s: float  # of the whole batch this sweep was simulated in
    output: str = "position"   # whose error: a root's position; a follower's l, phi, l1 or l2
    unit: str = "m"

    @property
    def values(self) -> np.ndarray:
        return self.errors[self.metric]

    @property
    def points(self) -> int:
        return int(np.prod([a.values.size for a in self.axes]))

    def trend(self) -> Trend:
        """The metric's trend along a one-gain sweep."""
        if len(self.axes) != 1:
            raise ValueError("a trend is defined for one-gain sweeps only")
        return classify_trend(self.values)

    def best(self) -> dict[str, float]:
        """The grid point with the lowest metric: {gain: value}."""
        index = np.unravel_index(int(np.argmin(self.values)), self.values.shape)
        return {a.name: float(a.values[i]) for a, i in zip(self.axes, index)}

    def best_on_edge(self) -> list[str]:
        """The gains whose best value is the first or last of its grid (the optimum may lie
        outside the grid: extend it that way). Empty if the best point is inside (or the axis
        has a single value)."""
        index = np.unravel_index(int(np.argmin(self.values)), self.values.shape)
        return [a.name for a, i in zip(self.axes, index) if a.values.size > 1 and i in (0, a.values.size - 1)]

    def edge_warning(self) -> str | None:
        """A one-line warning if the best point lies on the grid's edge, else None."""
        edges = self.best_on_edge()
        if not edges:
            return None
        best, parts = self.best(), []
        for name in edges:
            side = "lowest" if best[name] == self._axis(name).values[0] else "highest"
            parts.append(f"{name} = {best[name]:g}, the {side} value swept")
        return (f"warning: the lowest {self.metric} error is on the edge of the grid ({'; '.join(parts)}): the "
                "optimum may lie outside it; extend the grid that way")

    def _axis(self, name: str) -> GainAxis:
        return next(a for a in self.axes if a.name == name)

    def rows(self) -> list[list[float]]:
        """One row per grid point: the gain values, then every error statistic."""
        grids = np.meshgrid(*(a.values for a in self.axes), indexing="ij")
        columns = [g.ravel() for g in grids] + [self.errors[s].ravel() for s in _STATISTICS]
        return np.column_stack(columns).tolist()

    def header(self) -> list[str]:
        return [a.name for a in self.axes] + [f"error_{s}" for s in _STATISTICS]

    def write_csv(self, path: Path) -> Path:
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(self.header())
            writer.writerows([[f"{v:.10g}" for v in row] for row in self.rows()])
        return Path(path)

    def to_dict(self) -> dict:
        out = {"scenario": self.scenario, "robot": self.robot, "controller": self.controller, "metric": self.metric,
               "output": self.output, "unit": self.unit,
               "axes": {a.name: a.values.tolist() for a in self.axes}, "points": self.points,
               "errors": {s: self.errors[s].tolist() for s in _STATISTICS}}
        out["best"] = {"point": self.best(), "value": float(self.values.min()), "on_edge": self.best_on_edge()}
        if len(self.axes) == 1:
            trend = self.trend()
            out["trend"] = {"word": trend.word, "runs": list(trend.runs)}
        out["timing"] = {"elapsed_s": self.elapsed_s}   # the only part that varies between runs
        return out

    def write_json(self, path: Path) -> Path:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False))
        return Path(path)

    def plot(self, path=None, ax=None):
        """A line (one gain) or a heat map (two gains) of the metric; saves to ``path``."""
        from nonholo.studies.plots import plot_sweep

        return plot_sweep(self, path, ax)


_STATISTICS = ("mean", "std", "rms", "max", "final")


def choose_robot(scenario: Scenario, gains: Sequence[str], name: str | None = None) -> Robot:
    """The robot whose gains are swept: ``name``, or the only robot whose controller has
    all ``gains`` (an error lists the candidates when several have)."""
    if name is not None:
        for robot in scenario.robots:
            if robot.name == name:
                return robot
        raise NonholoInputError(f"no robot named {name!r} (robots: {', '.join(r.name for r in scenario.robots)})")
    candidates = [r for r in scenario.robots if all(g in sweepable(r) for g in gains)]
    if len(candidates) == 1 or len(scenario.robots) == 1:
        return (candidates or scenario.robots)[0]
    if not candidates:
        raise NonholoInputError(f"no robot of {scenario.name} has the gains {', '.join(gains)}")
    raise NonholoInputError(f"several robots have the gains {', '.join(gains)}: choose one with --robot "
                            f"({', '.join(r.name for r in candidates)})")


def sweepable(robot) -> tuple[str, ...]:
    """What a sweep can vary on a robot: a root's gains; a follower's gains k1, k2, its
    castor offset d and its targets (l, phi or l1, l2)."""
    if isinstance(robot, Follower):
        return ("k1", "k2", "d", *robot.outputs)
    return robot.controller.controller.accepted_gains


def _with_values(robot: Follower, values: dict) -> Follower:
    targets = list(robot.targets)
    for j, name in enumerate(robot.outputs):
        if name in values:
            targets[j] = values.pop(name)
    return dataclasses.replace(robot, targets=tuple(targets), **values)


def sweep_robots(base: Robot, axes: Sequence[GainAxis], prefix: str = "", span: slice = slice(None)) -> list[Robot]:
    """One copy of ``base`` per grid point (row-major over ``axes``; only the points of
    ``span``, a chunk's), with that point's gains and the same start, limits, variant and
    ξ(0)."""
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise NonholoInputError(f"a gain is swept twice: {', '.join(names)}")
    grids = np.meshgrid(*(a.values for a in axes), indexing="ij")
    first = span.indices(grids[0].size)[0]
    points = zip(*(g.ravel()[span] for g in grids))
    if isinstance(base, Follower):
        return [_with_values(base, {n: float(v) for n, v in zip(names, point)}) for point in points]
    return [dataclasses.replace(base, name=f"{prefix}{base.name}#{index}",
                                controller=with_gains(base.controller, {n: float(v) for n, v in zip(names, point)}))
            for index, point in enumerate(points, first)]


def with_gains(config, values: dict):
    """``config`` (a ``ControllerConfig``) with the gains ``values`` changed and the others
    kept (``xi0`` included; an alias such as ``kp`` replaces the gains it sets)."""
    fixed = dict(config.gains)
    if config.xi0 is not None:
        fixed[config.controller.initial_gain] = config.xi0
    for alias, targets in config.controller.aliases.items():
        if alias in values:
            for target in targets:
                fixed.pop(target, None)
    return config.controller.configure({**fixed, **values}, config.variant)


@dataclass(frozen=True)
class SweepSpec:
    """One sweep of a batch: the robot of the scenario to vary and the gain axes."""

    axes: tuple[GainAxis, ...]
    robot: str | None = None


def run_sweeps(scenario: Scenario, specs: Sequence[SweepSpec], metric: str = "mean", steps: int | None = None,
               progress: bool | None = None, dask: str | None = None, text: str | None = None,
               source: str = "<scenario>", on_start=None) -> list[SweepResult]:
    """Several sweeps of one scenario simulated together as ONE batch (one ``simulate``
    call, statistics only); ``steps`` overrides the scenario's number of output steps.

    ``dask`` ("local" or a scheduler address; needs the scenario's TOML ``text``) spreads
    chunks of the batch over a Dask cluster (``nonholo.studies.distributed``). Lone robots'
    results do not depend on their batch, so the chunks give the one batch's numbers; sweeps
    of formations are cut into the same chunks here and there. ``on_start()``, if given, is
    called once the robots and gains are checked, before the first simulation."""
    if metric not in METRICS:
        raise NonholoInputError(f"unknown metric {metric!r} (valid: {', '.join(METRICS)})")
    if dask is not None and text is None:
        raise NonholoInputError("a sweep on Dask needs the scenario's TOML text (workers parse it)")
    if steps is not None:
        scenario = dataclasses.replace(scenario, dt=None, steps=steps)
    for spec, base in zip(specs, _spans(scenario, specs)[1]):   # robots and gains checked before any run
        sweep_robots(base, [dataclasses.replace(a, values=np.array([a.values.min(), a.values.max()]))
                            for a in spec.axes])   # (a gain's rules are intervals: its extremes tell)
    if on_start is not None:
        on_start()
    payload = {"scenario": scenario, "text": text, "source": source, "steps": steps, "progress": progress,
               "specs": [(spec.robot, [(a.name, a.values) for a in spec.axes]) for spec in specs]}
    started = time.perf_counter()
    graph = bool(scenario.followers or any(r.posture for r in scenario.roots))
    outputs = []
    with distributed.dask_client(dask) as client:
        for which in (range(len(specs)) if graph else [None]):
            count, work = _sweep_size(scenario, specs, which)
            bounds = distributed.chunk_bounds(count, work) if graph or client is not None else [(0, count)]
            chunks = [{**payload, "which": which, "range": r} for r in bounds]
            if client is not None:
                chunks = [{**{k: v for k, v in c.items() if k != "scenario"}, "progress": False} for c in chunks]
            errors = [None] * len(bounds)
            for index, part in distributed.run_chunks(sweep_chunk, chunks, client):
                errors[index] = part
            outputs.append({s: np.concatenate([e[s] for e in errors]) for s in _STATISTICS})
    elapsed = time.perf_counter() - started
    sweeps = []
    spans, bases = _spans(scenario, specs)
    for number, (spec, base) in enumerate(zip(specs, bases)):
        shape = tuple(a.values.size for a in spec.axes)
        errors = outputs[number] if graph else {s: outputs[0][s][spans[number]] for s in _STATISTICS}
        law = base.law if isinstance(base, Follower) else base.controller.name
        output, unit = swept_output(base, spec)
        sweeps.append(SweepResult(scenario.name, base.name, law, tuple(spec.axes), metric,
                                  {s: errors[s].reshape(shape).copy() for s in _STATISTICS}, elapsed, output, unit))
    return sweeps


def swept_output(base, spec: SweepSpec) -> tuple[str, str]:
    """Whose error a sweep reports, and its unit: a root's position error; a follower's
    second output (φ or l2) when every swept parameter drives it (k2, phi, l2), else its
    first (l or l1): an l–φ follower's separation does not depend on its bearing's gain."""
    if not isinstance(base, Follower):
        return "position", "m"
    second = all(a.name in SECOND_OUTPUT_PARAMETERS for a in spec.axes)
    name = base.outputs[1 if second else 0]
    return name, "rad" if name == "phi" else "m"


def _output_statistics(metrics, index, output: str) -> dict:
    """The sweep's statistics (``_STATISTICS``) of robot ``index`` (an index or a slice) for
    ``output``: the first output's are the kernel's error statistics, the second's its
    heading statistics (its std from its mean and rms)."""
    if output not in ("phi", "l2"):
        return {s: np.atleast_1d(getattr(metrics, f"error_{s}")[index]) for s in _STATISTICS}
    mean, rms = np.atleast_1d(metrics.heading_mean[index]), np.atleast_1d(metrics.heading_rms[index])
    return {"mean": mean, "std": np.sqrt(np.maximum(rms * rms - mean * mean, 0.0)), "rms": rms,
            "max": np.atleast_1d(metrics.heading_max[index]), "final": np.atleast_1d(metrics.heading_final[index])}


def _specs(pairs) -> list[SweepSpec]:
    return [SweepSpec(tuple(GainAxis(name, np.asarray(values)) for name, values in axes), robot)
            for robot, axes in pairs]


def _spans(scenario: Scenario, specs: Sequence[SweepSpec]):
    """Each spec's slice of the robots of a tracking batch, and its base robot."""
    spans, bases, start = [], [], 0
    for spec in specs:
        if not 1 <= len(spec.axes) <= 2:
            raise NonholoInputError(f"sweep one or two gains, got {len(spec.axes)}")
        bases.append(choose_robot(scenario, [a.name for a in spec.axes], spec.robot))
        points = int(np.prod([a.values.size for a in spec.axes]))
        spans.append(slice(start, start + points))
        start += points
    return spans, bases


def _sweep_size(scenario: Scenario, specs: Sequence[SweepSpec], which: int | None) -> tuple[int, float]:
    """Items of one batch (robots of the tracking batch, or members of sweep ``which``) and
    the work of one item in robot-steps."""
    spans, _ = _spans(scenario, specs)
    steps = scenario.n_steps * (scenario.substeps or 1)
    if which is None:
        return spans[-1].stop, steps
    return spans[which].stop - spans[which].start, steps * len(scenario.robots)


def sweep_chunk(payload: dict) -> dict:
    """The error statistics of items ``range`` of one batch of a sweep (a worker's unit):
    the robots of the tracking batch (``which`` None) or the members of graph sweep
    ``which``. ``payload`` has the ``scenario`` (in this process) or its TOML ``text``."""
    scenario = payload.get("scenario")
    if scenario is None:
        scenario = distributed.scenario_of(payload["text"], payload["source"])
        if payload["steps"] is not None:
            scenario = dataclasses.replace(scenario, dt=None, steps=payload["steps"])
    specs = _specs(payload["specs"])
    a, b = payload["range"]
    if payload["which"] is None:
        robots = []
        for number, (spec, span, base) in enumerate(zip(specs, *_spans(scenario, specs))):
            lo, hi = max(a, span.start) - span.start, min(b, span.stop) - span.start   # the chunk's robots only
            if lo < hi:
                robots += sweep_robots(base, spec.axes, f"{number}:" if len(specs) > 1 else "", slice(lo, hi))
        batch = dataclasses.replace(scenario, robots=tuple(robots), steps=None, name=f"{scenario.name}-sweep")
        metrics = simulate(batch, record=False, progress=payload["progress"]).metrics
        return _output_statistics(metrics, slice(None), "position")
    spec = specs[payload["which"]]
    base = choose_robot(scenario, [x.name for x in spec.axes], spec.robot)
    index = scenario.names.index(base.name)
    members = [dataclasses.replace(scenario, robots=scenario.robots[:index] + (robot,) + scenario.robots[index + 1:],
                                   steps=None, name=f"{scenario.name}-sweep")
               for robot in sweep_robots(base, spec.axes, span=slice(a, b))]
    metrics = simulate(members, record=False, progress=payload["progress"]).metrics
    return _output_statistics(metrics, index, swept_output(base, spec)[0])


def run_sweep(scenario: Scenario, axes: Sequence[GainAxis], robot: str | None = None, metric: str = "mean",
              steps: int | None = None, progress: bool | None = None, **options) -> SweepResult:
    """Simulate the grid of ``axes`` (one or two gains) for one robot of ``scenario`` as
    one batch (see ``run_sweeps``; ``options``: ``dask``, ``text``, ``source``)."""
    return run_sweeps(scenario, [SweepSpec(tuple(axes), robot)], metric, steps, progress, **options)[0]
