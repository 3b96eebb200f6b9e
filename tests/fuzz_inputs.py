"""A longer fuzz run of the input side (issue 10): random and mutated formulas, waypoints,
scenario files and analysis system files, each of which must end in a result or in one
line of a ``NonholoInputError``, within a time bound.

    PYTHONPATH=. python3 tests/fuzz_inputs.py --seconds 600 [--seed 1]

prints the cases tried per kind, the slowest case and every finding (an exception of
another type, a message of several lines or too long, a case over the time bound); the
exit code is 1 if there was a finding. ``tests/test_hostile_inputs.py`` runs a short,
seeded version.
"""
from __future__ import annotations

import argparse
import contextlib
import random
import signal
import sys
import time
import traceback
import warnings
from pathlib import Path

import numpy as np

from nonholo import parse_scenario, references
from nonholo.analysis import load_system_file
from nonholo.errors import NonholoInputError

SLOW = 3.0  # seconds: a case slower than this is a finding
MAX_TEXT = 2_000_000  # characters of one mutated input (beyond every limit under test)
EXAMPLES = Path(__file__).resolve().parents[1] / "nonholo" / "examples"

ATOMS = ["t", "t", "t", "a", "pi", "E", "0", "1", "2", "3", "0.5", "1e-300", "1e300", "1e400", "10", "1000",
         "99999999999999999999", "zoo", "x", "sign", "ｔ"]
FUNCTIONS = ["sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "exp", "log", "sqrt", "Abs",
             "abs", "atan2", "floor", "__import__", "eval"]
OPERATORS = ["+", "-", "*", "/", "**", "^"]
JUNK = [".", "[", "]", "{", "}", "'", '"', "#", "\x00", "\u202e", ",", ":", "=", "==", "lambda", "if", "(", ")",
        "_", "1_0", "0x1", "1j", "\\", "\n", " ", "\u2212", "@", "%", "//", "~", "not", "for", "in", "f'"]


def formula(rng: random.Random, depth: int = 0) -> str:
    """A random formula from a loose grammar: mostly well formed, sometimes deep or huge."""
    roll = rng.random()
    if depth > rng.choice((3, 6, 12, 40)) or roll < 0.3:
        return rng.choice(ATOMS)
    if roll < 0.55:
        return f"{formula(rng, depth + 1)} {rng.choice(OPERATORS)} {formula(rng, depth + 1)}"
    if roll < 0.65:
        return f"{rng.choice('+-')}{formula(rng, depth + 1)}"
    if roll < 0.85:
        name = rng.choice(FUNCTIONS)
        arguments = [formula(rng, depth + 1) for _ in range(2 if name == "atan2" else 1)]
        return f"{name}({', '.join(arguments)})"
    if roll < 0.93:
        return f"({formula(rng, depth + 1)})"
    return rng.choice(OPERATORS).join(rng.choice(ATOMS) for _ in range(rng.choice((3, 50, 400, 3000))))


def mutate(rng: random.Random, text: str) -> str:
    """``text`` with a few random edits: characters or junk inserted, deleted, repeated."""
    for _ in range(rng.randint(1, 4)):
        i = rng.randrange(len(text) + 1)
        action = rng.random()
        if action < 0.3:
            text = text[:i] + rng.choice(JUNK + OPERATORS + ATOMS) + text[i:]
        elif action < 0.5 and text:
            text = text[:i] + text[i + 1:]
        elif action < 0.6:
            j = rng.randrange(i, len(text) + 1)
            text = text[:i] + text[i:j] * min(rng.choice((2, 10, 1000)), MAX_TEXT // max(1, j - i)) + text[j:]
        elif action < 0.7:
            text = text[:i] + chr(rng.randrange(1, 0x3000)) + text[i:]
        else:
            text = text[:i] + rng.choice(("(" * 50, "-" * 100, "[" * 40, "**" * 20, "{a=" * 40)) + text[i:]
        text = text[:MAX_TEXT]
    return text


CURRENT = [""]  # the input of the case being run, for the report


def case_formula(rng: random.Random):
    x, y = formula(rng), rng.choice(("t", "2*t", formula(rng)))
    if rng.random() < 0.4:
        x = mutate(rng, x)
    parameters = rng.choice((None, {"a": 0.5}, {"a": rng.choice((1e308, -0.0, 3))},
                             {rng.choice(("t", "x", "kind", "sin", "b", "lambda")): 1}))
    CURRENT[0] = f"x={x!r} y={y!r} parameters={parameters!r}"
    ref = references.expression(x, y, parameters=parameters)
    with np.errstate(all="ignore"):
        ref.table(np.linspace(0.0, 10.0, 11))


def case_waypoints(rng: random.Random):
    n = rng.choice((0, 1, 2, 3, 5, 50))
    times = np.cumsum(rng.choice(([1.0] * n, [rng.uniform(-1, 2) for _ in range(n)], [1e-300] * n, [1e300] * n)))
    times = times - times[0] if n and rng.random() < 0.8 else times
    points = [[float(t), rng.uniform(-10, 10), rng.choice((rng.uniform(-10, 10), float("nan"), 1e308))]
              for t in times]
    if len(points) > 1 and rng.random() < 0.3:
        points[-1][1:] = points[0][1:]
    if points and rng.random() < 0.3:
        points[rng.randrange(len(points))] = rng.choice(([1, 2], "a", [1, 2, "3"], [True, 1, 1], None))
    boundary = rng.choice(("not-a-knot", "natural", "clamped", "periodic", "bad"))
    CURRENT[0] = f"points={points!r} boundary={boundary!r}"
    ref = references.waypoints(points, boundary)
    t0, t1 = ref.time_span
    ref.table(np.linspace(max(t0, 0.0), t1, 7))


def case_scenario(rng: random.Random):
    examples = sorted(EXAMPLES.glob("*.toml"))
    text = mutate(rng, rng.choice(examples).read_text())
    CURRENT[0] = repr(text)
    parse_scenario(text, "fuzz.toml")


SYSTEM = """states = ["z1", "z2", "z3", "z4"]
inputs = ["u1", "u2"]
outputs = ["z1", "z4"]
[fields]
u1 = ["1", "0", "z2", "z3"]
u2 = ["0", "1", "0", "0"]
[parameters]
L = 0.5
"""


def case_system(rng: random.Random, directory: Path):
    path = directory / "system.toml"
    text = mutate(rng, SYSTEM)
    CURRENT[0] = repr(text)
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    load_system_file(path)


KINDS = ("formula", "waypoints", "scenario", "system")
HUNG = 30.0  # seconds after which a case is stopped (where SIGALRM exists)


class Hung(Exception):
    """A case stopped by the watchdog."""


@contextlib.contextmanager
def _watchdog(seconds: float):
    """Raise ``Hung`` in the case running after ``seconds`` (Unix; elsewhere no watchdog)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def stop(signum, frame):
        raise Hung()

    previous = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run(seconds: float, seed: int, directory: Path, kinds=KINDS, out=sys.stdout, keep=None,
        cases: int | None = None) -> list[str]:
    """Fuzz ``kinds`` of input for ``seconds`` (or ``cases`` cases); the findings (empty if
    none). The inputs of slow cases are appended to ``keep`` if given."""
    rng = random.Random(seed)
    runners = {"formula": case_formula, "waypoints": case_waypoints, "scenario": case_scenario,
               "system": lambda r: case_system(r, directory)}
    kinds = {kind: runners[kind] for kind in kinds}
    counts = {kind: [0, 0] for kind in kinds}  # tried, refused
    findings, slowest = [], (0.0, "")
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and (cases is None or sum(c[0] for c in counts.values()) < cases):
        kind = rng.choice(list(kinds))
        CURRENT[0] = ""
        started = time.perf_counter()
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings(), _watchdog(HUNG):
                warnings.simplefilter("ignore")  # scipy's ill-conditioning warnings are expected here
                kinds[kind](rng)
        except Hung:
            findings.append(f"{kind}: still running after {HUNG:.0f} s, stopped, for {CURRENT[0][:300]}")
            if keep is not None:
                keep.append(CURRENT[0])
        except NonholoInputError as exc:
            counts[kind][1] += 1
            message = str(exc)
            if "\n" in message or len(message) > 400:
                findings.append(f"{kind}: message of {len(message):,} characters / {message.count(chr(10)) + 1} "
                                f"lines: {message[:150]!r} for {CURRENT[0][:300]}")
        except Exception as exc:
            findings.append(f"{kind}: {type(exc).__name__}: {str(exc)[:200]} for {CURRENT[0][:300]}\n"
                            + "".join(traceback.format_tb(exc.__traceback__)[-2:]))
        elapsed = time.perf_counter() - started
        counts[kind][0] += 1
        if elapsed > slowest[0]:
            slowest = (elapsed, kind)
        if elapsed > SLOW:
            findings.append(f"{kind}: took {elapsed:.1f} s for {CURRENT[0][:300]}")
            if keep is not None:
                keep.append(CURRENT[0])
    for kind, (tried, refused) in counts.items():
        print(f"{kind:10s} {tried:7,d} cases, {refused:7,d} refused with one line", file=out)
    print(f"slowest case {slowest[0]:.2f} s ({slowest[1]}); findings: {len(findings)}", file=out)
    for finding in findings:
        print(finding, file=out)
    return findings


def main() -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        return 1 if run(args.seconds, args.seed, Path(directory)) else 0


if __name__ == "__main__":
    sys.exit(main())
