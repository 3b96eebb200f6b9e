"""Bundled example scenarios: the four thesis tests and an expression reference."""
from __future__ import annotations

from importlib import resources
from pathlib import Path


def names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files(__name__).iterdir() if p.name.endswith(".toml"))


def resolve(name: str) -> Path:
    """``name`` as a file path if it exists (or ends in .toml), else the bundled example of
    that name, else the path as given (so that reading it reports the missing file)."""
    candidate = Path(name)
    if candidate.exists() or candidate.suffix == ".toml" or name not in names():
        return candidate
    return path(name)


def path(name: str) -> Path:
    """The file of the bundled example ``name`` (KeyError listing the names if unknown)."""
    candidate = resources.files(__name__) / f"{name}.toml"
    if not candidate.is_file():
        raise KeyError(f"no bundled example {name!r} (examples: {', '.join(names())})")
    return Path(str(candidate))
