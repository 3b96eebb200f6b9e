"""Bundled example scenarios: the four thesis tests, an expression reference, formations and
posture stabilisation. ``nonholo examples`` lists them with a line each (``DESCRIPTIONS``:
the scenario schema has no top-level description field, so the lines live here).

>>> "test1-eight" in names() and all(name in DESCRIPTIONS for name in names())
True
>>> resolve("test5")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
nonholo.errors.NonholoInputError: test5: no such file and no bundled example of that name (did you mean ...) — examples: expression, ..., test4-circle (nonholo examples describes them)
"""
from __future__ import annotations

import difflib
from importlib import resources
from pathlib import Path

DESCRIPTIONS = {
    "expression": "reference from formulas x(t), y(t); dynamic feedback, actuator limits",
    "formation-chain": "7 l-phi followers in a chain behind a leader on the figure eight",
    "formation-circle-switch": "thesis Eq 5.8-5.9: l-phi follower on the circle, bearing switch at 100 s",
    "formation-eight-triangle": "thesis Eq 5.10: l-phi follower R2, l-l follower F, on the figure eight",
    "posture-dynamic-feedback": "thesis §5.7: dynamic-feedback posture law, (-10, -10) to (-10, 10)",
    "posture-polar": "thesis §5.7: polar-coordinate posture law, (-10, -10) to (-10, 10)",
    "posture-time-varying": "thesis §5.7: time-varying posture law, (-10, -10) to (-10, 10)",
    "test1-eight": "thesis Test 1: figure eight, every tracking law from the origin, 80π s",
    "test2-line": "thesis Test 2: straight line, every tracking law from the origin, 500 s",
    "test3-sinusoid": "thesis Test 3: sinusoid, every tracking law from the origin, 1000 s",
    "test4-circle": "thesis Test 4: circle, every tracking law from its centre, 40π s",
}


def names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files(__name__).iterdir() if p.name.endswith(".toml"))


def describe(name: str) -> str:
    """The one-line description of bundled example ``name``."""
    return DESCRIPTIONS.get(name, "")


def resolve(name: str) -> Path:
    """``name`` as a file path if it exists, ends in .toml or names a folder (reading it then
    reports a missing file), else the bundled example of that name; an unknown bare name
    raises NonholoInputError listing the bundled examples (the CLI exits with code 2)."""
    candidate = Path(name)
    if candidate.exists() or candidate.suffix == ".toml":
        return candidate
    if name in names():
        return path(name)
    if "/" in name or "\\" in name:
        return candidate
    from nonholo.errors import NonholoInputError

    close = difflib.get_close_matches(name, names(), n=3, cutoff=0.5)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    raise NonholoInputError(f"{name}: no such file and no bundled example of that name{hint} — examples: "
                            f"{', '.join(names())} (nonholo examples describes them)")


def path(name: str) -> Path:
    """The file of the bundled example ``name`` (KeyError listing the names if unknown)."""
    candidate = resources.files(__name__) / f"{name}.toml"
    if not candidate.is_file():
        raise KeyError(f"no bundled example {name!r} (examples: {', '.join(names())})")
    return Path(str(candidate))
