"""Monte-Carlo robustness: numbers of a scenario drawn from distributions, every sample
simulated (statistics only, in batches), and the distributions of the metrics, the failure
probabilities and the worst samples reported.

>>> Distribution.parse("normal(0, 0.5)")
Distribution(kind='normal', a=0.0, b=0.5)
>>> Distribution.parse("uniform(0.5, 1.5)").describe()
'uniform(0.5, 1.5)'

**Fields** (``ROBOT.PATH``): a root's ``start.x|y|theta``, ``gains.NAME`` (any gain of its
law, aliases such as ``kp`` and ``xi0`` included), ``goal.x|y|theta`` (posture), ``v_max``,
``omega_max``; a follower's ``start.x|y|theta`` (in the frame its file gives: ``start`` in
the world, ``start_relative`` in its leader's frame; a follower placed in formation gets a
world start), ``gains.k1|k2``, ``d``, ``l``, ``phi`` (l–φ) or ``l1``, ``l2`` (l–l), ``v_max``,
``omega_max``. Values are absolute: ``leader.start.x=normal(0, 0.5)`` draws x itself.

**What is simulated.** Only the connected formations that a varied robot belongs to (a
robot's result depends on the formations simulated with it only through the shared sub-step
plan, to the last digits), ``chunk_bounds``
samples per batch; chunk boundaries depend only on the study, so results are the same in
this process and on a Dask cluster (``nonholo.studies.distributed``).

**Failures** per sample (any of its simulated robots): *diverged* (state non-finite or beyond 1e9 m, the
simulator's ``diverged``); *singular* (a singularity guard acted at some sample);
*saturated* (a robot's command clipped on more than ``saturation_share`` of the samples);
*collision* (two robots of a formation closer than 2d, d its largest castor offset).
Probabilities carry Wilson 95 % intervals; metric means carry normal 95 % intervals.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import time
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nonholo.errors import NonholoInputError
from nonholo.sim import kernel as kn
from nonholo.sim.result import Metrics
from nonholo.sim.links import LinkSettings
from nonholo.sim.scenario import SECOND_OUTPUT_PARAMETERS, Follower, Robot, Scenario
from nonholo.sim.simulator import diverged, simulate
from nonholo.studies import distributed
from nonholo.studies.sweep import with_gains

DISTRIBUTIONS = ("normal", "uniform")
AXES = ("x", "y", "theta")
# Per-robot metrics of every sample (names of the JSON and CSV columns: ROBOT.METRIC).
METRICS = ("error_mean", "error_rms", "error_max", "error_final", "heading_rms", "heading_max", "peak_v",
           "peak_omega", "effort", "saturated_share", "singular_samples")
# Per-formation metric (named after the formation's first robot): the closest pair's distance.
FORMATION_METRICS = ("min_distance",)
FAILURES = ("diverged", "singular", "saturated", "collision")
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
# ``--vary network.FIELD=DIST``: the scenario's link model, every link alike (spec fleet.md §3;
# the per-sample draws of delay and loss keep the scenario's [network] seed: common random
# numbers, so samples differ by the varied numbers only). FIELD: its range.
NETWORK = "network"
NETWORK_FIELDS = {"delay": (0.0, 3600.0), "jitter": (0.0, 3600.0), "loss": (0.0, 1.0)}
Z95 = 1.959963984540054
MAX_SAMPLES = 10_000_000
_NUMBER = r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*"
_DISTRIBUTION = re.compile(rf"^\s*([a-z]+)\s*\({_NUMBER},{_NUMBER}\)\s*$")


@dataclass(frozen=True)
class Distribution:
    """``normal(mu, sigma)`` or ``uniform(a, b)``, parsed by a regular expression (never eval)."""

    kind: str
    a: float
    b: float

    @classmethod
    def parse(cls, text: str) -> "Distribution":
        match = _DISTRIBUTION.match(text)
        if not match:
            raise NonholoInputError(f"distribution {text!r}: expected normal(MU, SIGMA) or uniform(A, B) with numbers")
        kind, a, b = match.group(1), float(match.group(2)), float(match.group(3))
        if kind not in DISTRIBUTIONS:
            raise NonholoInputError(f"distribution {text!r}: unknown kind {kind!r} (valid: {', '.join(DISTRIBUTIONS)})")
        if not (math.isfinite(a) and math.isfinite(b)):
            raise NonholoInputError(f"distribution {text!r}: parameters must be finite")
        if kind == "normal" and b < 0:
            raise NonholoInputError(f"distribution {text!r}: sigma must be >= 0")
        if kind == "uniform" and b < a:
            raise NonholoInputError(f"distribution {text!r}: uniform(A, B) needs A <= B")
        return cls(kind, a, b)

    def draw(self, rng: np.random.Generator, count: int) -> np.ndarray:
        if self.kind == "normal":
            return rng.normal(self.a, self.b, count)
        return rng.uniform(self.a, self.b, count)

    def describe(self) -> str:
        return f"{self.kind}({self.a:g}, {self.b:g})"


@dataclass(frozen=True)
class Variation:
    """One varied number: ``robot``'s ``path`` (e.g. "start.x", "gains.kp", "phi")."""

    robot: str
    path: str
    distribution: Distribution

    @property
    def field(self) -> str:
        return f"{self.robot}.{self.path}"

    @classmethod
    def parse(cls, text: str, scenario: Scenario) -> "Variation":
        """``ROBOT.PATH=DIST``, checked against the scenario (one-line errors name the field)."""
        where, sep, dist = text.partition("=")
        if not sep:
            raise NonholoInputError(f"--vary must look like ROBOT.FIELD=normal(MU, SIGMA), got {text!r}"[:200])
        where = where.strip()
        if where.startswith(NETWORK + "."):
            path = where[len(NETWORK) + 1:]
            if path not in NETWORK_FIELDS:
                raise NonholoInputError(f"--vary {where}: {path!r} is not a number of the link model "
                                        f"(valid: {', '.join(NETWORK_FIELDS)})"[:300])
            if scenario.hold_every == 0:
                raise NonholoInputError(f"--vary {where}: the link model needs sampled-data control: set "
                                        "[simulation] control_period in the scenario")
            return cls(NETWORK, path, Distribution.parse(dist))
        names = sorted((n for n in scenario.names if where.startswith(n + ".")), key=len, reverse=True)
        if not names:
            raise NonholoInputError(f"--vary {where}: no robot of that name (robots: {', '.join(scenario.names)})"[:300])
        robot = scenario.robot(names[0])
        path = where[len(names[0]) + 1:]
        valid = fields_of(robot)
        if path not in valid:
            raise NonholoInputError(f"--vary {where}: {path!r} is not a number of {robot.name} "
                                    f"(valid: {', '.join(valid)})"[:300])
        return cls(robot.name, path, Distribution.parse(dist))


def fields_of(robot) -> tuple[str, ...]:
    """The paths a variation can name on ``robot``."""
    starts = tuple(f"start.{a}" for a in AXES)
    limits = ("v_max", "omega_max")
    if isinstance(robot, Follower):
        return (*starts, "gains.k1", "gains.k2", "d", *robot.outputs, *limits)
    spec = robot.controller.controller
    gains = tuple(f"gains.{g}" for g in spec.accepted_gains)
    goal = tuple(f"goal.{a}" for a in AXES) if robot.posture else ()
    return (*starts, *gains, *goal, *limits)


def _number(values: dict, path: str, old: float) -> float:
    return float(values.get(path, old))


def _pose(values: dict, prefix: str, old) -> tuple[float, float, float]:
    return tuple(float(values.get(f"{prefix}.{a}", o)) for a, o in zip(AXES, old))


def vary_robot(robot, values: dict, world_start=None):
    """``robot`` with the numbers of ``values`` ({path: value}) changed. ``world_start``:
    the robot's start in the world, used when a follower placed in formation gets a start."""
    changes = {}
    if any(p.startswith("start.") for p in values):
        start = robot.start if robot.start is not None else world_start
        changes["start"] = _pose(values, "start", start)
    for limit in ("v_max", "omega_max"):
        if limit in values:
            changes[limit] = float(values[limit])
    if isinstance(robot, Follower):
        for name in ("k1", "k2"):
            if f"gains.{name}" in values:
                changes[name] = float(values[f"gains.{name}"])
        if "d" in values:
            changes["d"] = float(values["d"])
        if any(o in values for o in robot.outputs):
            changes["targets"] = tuple(_number(values, o, t) for o, t in zip(robot.outputs, robot.targets))
        return dataclasses.replace(robot, **changes)
    gains = {p[6:]: float(v) for p, v in values.items() if p.startswith("gains.")}
    if gains:
        changes["controller"] = with_gains(robot.controller, gains)
    if any(p.startswith("goal.") for p in values):
        changes["goal"] = _pose(values, "goal", robot.goal)
    return dataclasses.replace(robot, **changes)


def varied_part(scenario: Scenario, robots: Sequence[str]) -> Scenario:
    """The scenario restricted to the connected formations of ``robots`` (file order)."""
    wanted = {scenario.names.index(r) for r in robots}
    keep = sorted(i for c in scenario.components() if wanted & set(c) for i in c)
    if len(keep) == len(scenario.robots):
        return scenario
    return dataclasses.replace(scenario, robots=tuple(scenario.robots[i] for i in keep))


def sample_scenario(base: Scenario, fields: Sequence[tuple[str, str]], row: Sequence[float], name: str | None = None):
    """``base`` with the numbers ``row`` at ``fields`` ((robot, path) pairs)."""
    by_robot: dict[str, dict] = {}
    for (robot, path), value in zip(fields, row):
        by_robot.setdefault(robot, {})[path] = value
    link = by_robot.pop(NETWORK, None)
    if link:
        settings = base.network or LinkSettings()
        default = dataclasses.replace(settings.default, **{k: float(v) for k, v in link.items()})
        base = dataclasses.replace(base, network=dataclasses.replace(settings, default=default))
    world = None
    robots = list(base.robots)
    for i, robot in enumerate(robots):
        values = by_robot.get(robot.name)
        if values:
            if isinstance(robot, Follower) and robot.start is None and world is None:
                world = base.initial_poses()
            robots[i] = vary_robot(robot, values, world[i] if world is not None and robot.start is None else None)
    return dataclasses.replace(base, robots=tuple(robots), name=name or base.name)


def draw(variations: Sequence[Variation], samples: int, seed: int) -> np.ndarray:
    """(samples, variations) values: one ``default_rng(seed)`` stream, the variations drawn
    one after the other in the order given."""
    rng = np.random.default_rng(seed)
    return np.column_stack([v.distribution.draw(rng, samples) for v in variations]).reshape(samples, len(variations))


def metric_columns(scenario: Scenario) -> list[str]:
    """The per-sample metric columns of a (varied part of a) scenario."""
    columns = [f"{r.name}.{m}" for r in scenario.robots for m in METRICS]
    columns += [f"{scenario.robots[c[0]].name}.{m}" for c in scenario.components() if len(c) > 1 for m in FORMATION_METRICS]
    return columns


def simulate_chunk(payload: dict) -> dict:
    """Simulate one chunk of samples (a worker's unit): ``payload`` has the scenario's TOML
    ``text`` and ``source``, the ``robots`` kept, the varied ``fields``, the ``values``
    (chunk, variations), ``steps`` (or None) and ``saturation_share``. Returns ``metrics``
    (chunk, columns) and ``failures`` (chunk, FAILURES) arrays."""
    base = distributed.scenario_of(payload["text"], payload["source"])
    if payload["steps"] is not None:
        base = dataclasses.replace(base, dt=None, steps=payload["steps"])
    part = varied_part(base, payload["robots"])
    members = [sample_scenario(part, payload["fields"], row) for row in payload["values"]]
    result = simulate(members, record=False, progress=False, on_divergence="report")
    return sample_metrics(result, payload["saturation_share"])


def sample_metrics(result, saturation_share: float) -> dict:
    """Per-member metric columns (``metric_columns`` order) and failure flags of a batch."""
    stats, samples = result.stats, result.t.size
    members = stats.shape[2]
    m = Metrics.from_stats(stats, samples, float(result.t[-1]))
    saturated = stats[kn.SAT_ANY] / samples
    per_robot = {"error_mean": m.error_mean, "error_rms": m.error_rms, "error_max": m.error_max,
                 "error_final": m.error_final, "heading_rms": m.heading_rms, "heading_max": m.heading_max,
                 "peak_v": m.peak_v, "peak_omega": m.peak_omega, "effort": m.effort, "saturated_share": saturated,
                 "singular_samples": stats[kn.SINGULAR]}
    scenario = result.scenarios[0]
    columns = [np.asarray(per_robot[name], dtype=float)[i]
               for i in range(len(scenario.robots)) for name in METRICS]
    formations = [k for k, c in enumerate(scenario.components()) if len(c) > 1]
    columns += [result.pair_stats[kn.CLOSEST, k] for k in formations]
    bad = diverged(stats)
    metrics = np.column_stack(columns)
    collision = (result.pair_stats[kn.BELOW_ANY][formations] > 0).any(axis=0) if formations else np.zeros(members, bool)
    singular = (stats[kn.SINGULAR] > 0) | (stats[kn.SIN_CROSSINGS] > 0)   # (an l–l singularity crossed between samples)
    failures = np.column_stack([bad.any(axis=0), singular.any(axis=0),
                                (saturated > saturation_share).any(axis=0), collision])
    return {"metrics": metrics, "failures": failures}


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion.

    >>> [round(v, 4) for v in wilson(0, 100)]
    [0.0, 0.037]
    """
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def distribution_summary(values: np.ndarray) -> dict:
    """Mean (with a normal 95 % interval), std, min, max and quantiles of the finite values
    (a figure that overflows, e.g. the std of nearly diverged samples, is null)."""
    finite = values[np.isfinite(values)]
    n = int(finite.size)
    if n == 0:
        return {"n": 0}
    with np.errstate(over="ignore", invalid="ignore"):
        mean = float(finite.mean())
        std = float(finite.std(ddof=1)) if n > 1 else 0.0
        half = Z95 * std / math.sqrt(n)
        quantiles = np.quantile(finite, QUANTILES)
    f = _finite_or_none
    return {"n": n, "mean": f(mean), "mean_ci95": [f(mean - half), f(mean + half)], "std": f(std),
            "min": float(finite.min()), "max": float(finite.max()),
            "quantiles": {f"q{round(100 * q):02d}": f(v) for q, v in zip(QUANTILES, quantiles)}}


@dataclass
class MonteCarloResult:
    """A finished Monte-Carlo study: the drawn ``values`` (samples, variations), the
    per-sample ``metrics`` (samples, ``columns``) and ``failures`` (samples, FAILURES)."""

    scenario: str
    variations: tuple[Variation, ...]
    seed: int
    saturation_share: float
    simulated: tuple[str, ...]
    columns: list[str]
    values: np.ndarray
    metrics: np.ndarray
    failures: np.ndarray
    worst_by: str
    worst_count: int
    steps: int
    duration: float
    timing: dict = field(default_factory=dict)
    worst_files: dict = field(default_factory=dict)

    @property
    def samples(self) -> int:
        return self.values.shape[0]

    def column(self, name: str) -> np.ndarray:
        return self.metrics[:, self.columns.index(name)]

    def worst(self) -> list[int]:
        """Sample indices, worst first: diverged samples, then the largest ``worst_by``
        (ties by index)."""
        score = self.column(self.worst_by).copy()
        score[~np.isfinite(score)] = np.inf
        score[self.failures[:, 0]] = np.inf
        order = np.lexsort((np.arange(score.size), -score))
        return [int(i) for i in order[:self.worst_count]]

    def failure_summary(self) -> dict:
        n = self.samples
        out = {}
        for j, name in enumerate(FAILURES):
            count = int(self.failures[:, j].sum())
            out[name] = {"count": count, "probability": count / n, "ci95": list(wilson(count, n))}
        any_failure = int(self.failures.any(axis=1).sum())
        out["any"] = {"count": any_failure, "probability": any_failure / n, "ci95": list(wilson(any_failure, n))}
        return out

    def to_dict(self) -> dict:
        """JSON-ready; apart from ``timing`` it depends only on the scenario, options and seed."""
        worst = []
        for rank, i in enumerate(self.worst(), 1):
            entry = {"rank": rank, "sample": i, "values": {v.field: float(x) for v, x in zip(self.variations,
                                                                                           self.values[i])},
                     self.worst_by: _finite_or_none(self.column(self.worst_by)[i]),
                     "failures": [f for f, flag in zip(FAILURES, self.failures[i]) if flag]}
            if rank in self.worst_files:
                entry["file"] = self.worst_files[rank]
            worst.append(entry)
        return {"scenario": self.scenario, "samples": self.samples, "seed": self.seed,
                "simulation": {"steps": self.steps, "duration": self.duration},
                "vary": {v.field: v.distribution.describe() for v in self.variations},
                "simulated_robots": list(self.simulated), "saturation_share": self.saturation_share,
                "metrics": {c: distribution_summary(self.metrics[:, j]) for j, c in enumerate(self.columns)},
                "failures": self.failure_summary(), "worst_by": self.worst_by, "worst": worst,
                "timing": self.timing}

    def plot(self, path=None, columns: Sequence[str] | None = None, bins: int = 40):
        """Histograms of the metrics (default: each simulated robot's error_rms, error_max,
        effort and peak_omega, and each formation's min_distance), failures in the title."""
        import matplotlib

        if path is not None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        if columns is None:
            columns = [c for c in self.columns
                       if c.rsplit(".", 1)[1] in ("error_rms", "error_max", "effort", "peak_omega", "min_distance")]
        columns = list(columns)[:16]
        cols = min(4, max(1, len(columns)))
        rows = max(1, math.ceil(len(columns) / cols))
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.8 * rows + 0.6), squeeze=False)
        for ax, name in zip(axes.flat, columns):
            values = self.column(name)
            values = values[np.isfinite(values)]
            if values.size:
                ax.hist(values, bins=bins, color="#3a6ea5", edgecolor="white", linewidth=0.3)
                summary = distribution_summary(values)
                if summary["mean"] is not None:
                    ax.axvline(summary["mean"], color="#c0392b", linewidth=1.0, label="mean")
                if summary["quantiles"]["q95"] is not None:
                    ax.axvline(summary["quantiles"]["q95"], color="#555555", linewidth=1.0, linestyle="--",
                               label="q95")
            ax.set_title(name, fontsize=9)
            ax.tick_params(labelsize=7)
            ax.set_ylabel("samples", fontsize=8)
        for ax in list(axes.flat)[len(columns):]:
            ax.axis("off")
        if columns:
            axes.flat[0].legend(fontsize=7)
        failures = self.failure_summary()
        text = ", ".join(f"{name} {failures[name]['count']}" for name in FAILURES)
        fig.suptitle(f"{self.scenario}: {self.samples} samples (seed {self.seed}); failures: {text}", fontsize=10)
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=110)
            plt.close(fig)
        return fig


def _finite_or_none(value: float):
    return float(value) if math.isfinite(value) else None


def run_montecarlo(text: str, variations_text: Sequence[str], samples: int, seed: int = 0, source: str = "<scenario>",
                   steps: int | None = None, saturation_share: float = 0.05, worst: int = 5,
                   worst_by: str | None = None, out: Path | None = None, dask: str | None = None,
                   progress: bool | None = None, on_start=None) -> MonteCarloResult:
    """A Monte-Carlo study of the scenario of TOML ``text``: ``samples`` draws of the
    ``variations_text`` (``ROBOT.PATH=DIST``), seeded by ``seed``. ``out``: stream the
    samples to ``out/samples.csv`` chunk by chunk and write ``summary.json``,
    ``histograms.png`` and the ``worst`` samples as ``worst-K.toml``. ``dask``: None (this
    process), "local" or a scheduler address. ``on_start()``, if given, is called once the
    inputs are checked, before the first simulation (``nonholo montecarlo`` says it started)."""
    started = time.perf_counter()
    if not (isinstance(samples, int) and 1 <= samples <= MAX_SAMPLES):
        raise NonholoInputError(f"--samples must be an integer from 1 to {MAX_SAMPLES}, got {samples!r}")
    if steps is not None and steps < 1:
        raise NonholoInputError(f"--steps must be a positive integer, got {steps}")
    if not (0 <= saturation_share < 1):
        raise NonholoInputError(f"--saturation-share must be in [0, 1), got {saturation_share!r}")
    if worst < 0:
        raise NonholoInputError(f"--worst must be >= 0, got {worst}")
    distributed.check_address(dask)
    scenario = distributed.scenario_of(text, source)
    if steps is not None:
        scenario = dataclasses.replace(scenario, dt=None, steps=steps)
    if not variations_text:
        raise NonholoInputError("give at least one --vary ROBOT.FIELD=DIST")
    variations = tuple(Variation.parse(v, scenario) for v in variations_text)
    fields = [(v.robot, v.path) for v in variations]
    if len(set(fields)) != len(fields):
        raise NonholoInputError("--vary: a field is varied twice")
    if any(v.robot == NETWORK for v in variations):   # links reach every follower: the whole scenario
        part = scenario
    else:
        part = varied_part(scenario, [v.robot for v in variations])
    sample_scenario(part, fields, [_mean(v.distribution) for v in variations])  # checks the fields apply
    columns = metric_columns(part)
    affected = [v.robot for v in variations if v.robot != NETWORK] or \
        [r.name for r in part.robots if isinstance(r, Follower)] or [part.names[0]]   # links move followers
    # a follower's metrics: error_* of its first output (l, l1), heading_* of its second (φ, l2);
    # ranked by the one its first varied parameter drives
    drives = next((v.path.rsplit(".", 1)[-1] for v in variations if v.robot == affected[0]), "")
    second = isinstance(part.robots[part.names.index(affected[0])], Follower) and drives in SECOND_OUTPUT_PARAMETERS
    worst_by = worst_by or f"{affected[0]}.{'heading_max' if second else 'error_max'}"
    if worst_by not in columns:
        raise NonholoInputError(f"--worst-by {worst_by!r}: not a metric (e.g. {', '.join(columns[:4])}, …)"[:300])
    values = draw(variations, samples, seed)
    for k, variation in enumerate(variations):
        if variation.robot == NETWORK:
            low, high = NETWORK_FIELDS[variation.path]
            outside = int(np.count_nonzero(~((values[:, k] >= low) & (values[:, k] < high if variation.path == "loss"
                                                                         else values[:, k] <= high))))
            if outside:
                raise NonholoInputError(f"--vary {variation.field}: {outside} of {samples} draws fall outside "
                                        f"[{low:g}, {high:g}{')' if variation.path == 'loss' else ']'}: choose a "
                                        "distribution within the range (e.g. uniform)")
    means = [_mean(v.distribution) for v in variations]
    for k, variation in enumerate(variations):   # the extreme draws against the field's rules, one line
        for i in (int(np.argmin(values[:, k])), int(np.argmax(values[:, k]))):
            try:
                sample_scenario(part, fields, means[:k] + [values[i, k]] + means[k + 1:])
            except NonholoInputError as exc:
                raise NonholoInputError(f"--vary {variation.field}: sample {i} draws {values[i, k]:g}: {exc}; "
                                        "choose a distribution within the field's range (e.g. uniform)") from None
    if on_start is not None:
        on_start()
    robots = [r.name for r in part.robots]
    work = len(robots) * part.n_steps * (part.substeps or 1)
    bounds = distributed.chunk_bounds(samples, work)
    payloads = [{"text": text, "source": source, "robots": robots, "fields": fields, "values": values[a:b],
                 "steps": steps, "saturation_share": saturation_share} for a, b in bounds]
    metrics = np.empty((samples, len(columns)))
    failures = np.zeros((samples, len(FAILURES)), dtype=bool)
    writer = _SampleWriter(out, variations, columns, values, bounds) if out is not None else None
    simulate_started = time.perf_counter()
    try:
        with distributed.dask_client(dask) as client, \
                distributed.progress_bar(samples, "sample", f"{scenario.name}: Monte-Carlo", progress) as bar:
            for index, chunk in distributed.run_chunks(simulate_chunk, payloads, client,
                                                       lambda k: bar.update(bounds[k][1] - bounds[k][0])):
                a, b = bounds[index]
                metrics[a:b], failures[a:b] = chunk["metrics"], chunk["failures"]
                if writer is not None:
                    writer.add(index, metrics, failures)
    finally:
        if writer is not None:
            writer.close()
    simulate_s = time.perf_counter() - simulate_started
    result = MonteCarloResult(scenario.name, variations, seed, saturation_share, tuple(robots), columns, values,
                              metrics, failures, worst_by, worst, part.n_steps, float(part.duration))
    if out is not None:
        result.worst_files = write_worst(result, text, source, Path(out), steps)
        result.plot(Path(out) / "histograms.png")
    result.timing = {"total_s": time.perf_counter() - started, "simulate_s": simulate_s, "chunks": len(bounds),
                     "samples_per_s": samples / simulate_s if simulate_s > 0 else None,
                     "dask": dask is not None}
    if out is not None:
        (Path(out) / "summary.json").write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False))
    return result


def _mean(distribution: Distribution) -> float:
    return distribution.a if distribution.kind == "normal" else (distribution.a + distribution.b) / 2


class _SampleWriter:
    """``samples.csv``, appended chunk by chunk in sample order (chunks that finish early
    wait for their predecessors)."""

    def __init__(self, out: Path, variations, columns, values, bounds):
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.handle = open(out / "samples.csv", "w", newline="")
        self.csv = csv.writer(self.handle)
        self.csv.writerow(["sample", *(v.field for v in variations), *columns, *FAILURES])
        self.values, self.bounds, self.done, self.next = values, bounds, set(), 0

    def add(self, index: int, metrics: np.ndarray, failures: np.ndarray) -> None:
        self.done.add(index)
        while self.next in self.done:
            a, b = self.bounds[self.next]
            for i in range(a, b):
                self.csv.writerow([i, *(f"{v:.10g}" for v in self.values[i]), *(f"{v:.10g}" for v in metrics[i]),
                                   *(int(f) for f in failures[i])])
            self.handle.flush()
            self.next += 1

    def close(self) -> None:
        self.handle.close()


# ---------------------------------------------------------------------- re-runnable files
def write_worst(result: MonteCarloResult, text: str, source: str, out: Path, steps: int | None = None) -> dict[int, str]:
    """The worst samples as scenario files ``worst-K.toml`` (the original file with the
    sample's numbers); {rank: file name}."""
    files = {}
    for rank, i in enumerate(result.worst(), 1):
        data = patched_toml(text, result.variations, result.values[i], source)
        name = f"worst-{rank}.toml"
        header = (f"# Monte-Carlo sample {i} of {result.samples} (seed {result.seed}) of {source}, rank {rank} by "
                  f"{result.worst_by}:\n" + "".join(f"#   {v.field} = {float(x)!r}\n" for v, x in zip(result.variations,
                                                                                              result.values[i])))
        data["name"] = f"{result.scenario}-sample-{i}"
        if steps is not None:
            simulation = data.setdefault("simulation", {})
            simulation.pop("dt", None)
            simulation["steps"] = steps
        (out / name).write_text(header + toml_text(data))
        files[rank] = name
    return files


def patched_toml(text: str, variations: Sequence[Variation], row: Sequence[float], source: str = "<scenario>") -> dict:
    """The TOML data of ``text`` with the numbers ``row`` at the ``variations``' fields."""
    data = tomllib.loads(text)
    scenario = distributed.scenario_of(text, source)
    poses = None
    for variation, value in zip(variations, row):
        if variation.robot == NETWORK:
            data.setdefault("network", {})[variation.path] = float(value)
            continue
        index = scenario.names.index(variation.robot)
        robot, entry, value = scenario.robots[index], data["robots"][index], float(value)
        head, _, tail = variation.path.partition(".")
        if head in ("start", "goal"):
            key = head
            if head == "start" and isinstance(robot, Follower):
                if "start_relative" in entry:
                    key = "start_relative"
                elif "start" not in entry:
                    poses = poses or scenario.initial_poses()
                    entry["start"] = list(poses[index])
            entry.setdefault(key, [0.0, 0.0, 0.0])
            entry[key] = list(entry[key])
            entry[key][AXES.index(tail)] = value
        elif head == "gains":
            gains = entry.setdefault("gains", {})
            if isinstance(robot, Robot):
                spec = robot.controller.controller
                for alias, targets in spec.aliases.items():
                    if tail in targets and alias in gains:      # expand an alias before changing one of its gains
                        old = gains.pop(alias)
                        for target in targets:
                            gains.setdefault(target, old)
                    if tail == alias:
                        for target in targets:
                            gains.pop(target, None)
            gains[tail] = value
        elif head in ("l1", "l2"):
            entry["l"] = list(entry["l"])
            entry["l"][0 if head == "l1" else 1] = value
        else:
            entry[head] = value
    return data


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key)


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("nan" if math.isnan(value) else
                                                          ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def toml_text(data: dict, prefix: str = "") -> str:
    """TOML text of plain data (what ``tomllib.loads`` gives): scalars, arrays and small
    tables inline, other tables as [sections], lists of tables as [[sections]].

    >>> print(toml_text({"name": "a", "robots": [{"name": "r", "gains": {"kp": 1.0}}]}).strip())
    name = "a"
    <BLANKLINE>
    [[robots]]
    name = "r"
    gains = { kp = 1.0 }
    """
    lines, sections = [], []
    for key, value in data.items():
        if isinstance(value, dict) and (prefix == "" or any(isinstance(v, (dict, list)) for v in value.values())):
            sections.append((key, value, False))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            sections.append((key, value, True))
        else:
            lines.append(f"{_key(key)} = {_value(value)}")
    text = "\n".join(lines) + ("\n" if lines else "")
    for key, value, array in sections:
        name = f"{prefix}.{_key(key)}" if prefix else _key(key)
        if array:
            for item in value:
                text += f"\n[[{name}]]\n" + toml_text(item, name)
        else:
            text += f"\n[{name}]\n" + toml_text(value, name)
    return text
