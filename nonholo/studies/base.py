"""The study registry convention.

A *study* is a reproducible experiment that writes one section of the report. Every
module of ``nonholo.studies`` that defines a module-level ``STUDY`` (a ``Study``) is
discovered by ``discover()``, the way ``nonholo.cli`` discovers commands, so adding a study
(``formation.py``, ``posture.py``…) never edits this package's other files.

``Study.run(options) -> StudyResult``. A ``StudyResult`` carries its data and knows how to
present itself: ``text()`` for the terminal (at most 100 columns: summaries; the wide
tables go to the report and CSV), ``html_section(folder, draw)`` for the report
(it hands each figure's drawing to ``draw``, which writes it into ``folder``, and returns an
HTML fragment that refers to the figures by relative path), ``write_data(folder)`` for CSV/JSON, ``to_dict()`` and ``ok``.

A study may also say how to compile ahead what its run will compile (``Study.warm_up``,
often ``run_briefly`` over its cases): ``nonholo study`` runs the later studies' warm-ups in a
forked child while the first study runs (``studies.report.each_result``), so that a first
run's compiling overlaps, and a later study loads its kernels from the disk cache.
"""
from __future__ import annotations

import dataclasses
import importlib
import pkgutil
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from nonholo.studies.forking import MAX_PROCESSES, draw_now

SAMPLINGS = ("uniform", "solver-steps", "both")


@dataclass(frozen=True)
class StudyOptions:
    """What every study is told: where to write, how thorough to be, whether to show
    progress (a bar on a terminal, one-line logs elsewhere), and which statistics to take (``SAMPLINGS``; studies without a
    variable-step variant ignore it)."""

    out_dir: Path
    quick: bool = False
    progress: bool = True
    sampling: str = "both"
    processes: int = 0   # forked helpers at once: figures, independent parts (0: all here; ``studies.forking``)

    def __post_init__(self):
        if not isinstance(self.processes, int) or not 0 <= self.processes <= MAX_PROCESSES:
            from nonholo.errors import NonholoInputError

            raise NonholoInputError(f"processes must be a whole number from 0 to {MAX_PROCESSES}, not "
                                    f"{self.processes!r}")
        if self.sampling not in SAMPLINGS:
            from nonholo.errors import NonholoInputError

            raise NonholoInputError(f"unknown sampling {self.sampling!r} (valid: {', '.join(SAMPLINGS)})")
        object.__setattr__(self, "out_dir", Path(self.out_dir))

    def progress_for(self, label: str, total: int, unit: str = "steps"):
        """A ``Progress`` for ``total`` steps of this study: a bar on a terminal, one-line logs
        elsewhere, nothing if ``progress`` is False (``nonholo.studies.progress``)."""
        from nonholo.studies.progress import Progress, mode_for

        return Progress(label, total, mode_for(self.progress), unit)

    def folder(self, study: str) -> Path:
        """The study's own folder inside the report (created)."""
        path = self.out_dir / study
        path.mkdir(parents=True, exist_ok=True)
        return path


class StudyResult(ABC):
    """What a study returns (see the module docstring)."""

    name: str
    title: str
    elapsed_s: float  # wall time of the study's simulations and statistics (not of its figures)
    spec_file: str = "leader.md"  # the specification file its citations ("spec §5.3", "erratum 19") refer to

    @property
    def ok(self) -> bool:
        """False if the study found something that should fail the command (exit code 1)."""
        return True

    @abstractmethod
    def text(self) -> str:
        """Plain-text summary for the terminal."""

    @abstractmethod
    def html_section(self, folder: Path, draw: Callable = draw_now) -> str:
        """An HTML fragment (figures written into ``folder``, referred to relatively
        from the report's ``index.html`` one level up); each figure is drawn by handing the
        call to ``draw`` (``draw(plot, data, folder / "name.png")``), which may draw it later,
        in another process (``nonholo.studies.forking``): the fragment names the file only."""

    @abstractmethod
    def write_data(self, folder: Path) -> list[Path]:
        """CSV/JSON files of the results; returns their paths."""

    @abstractmethod
    def to_dict(self) -> dict:
        """JSON-ready results."""


@dataclass(frozen=True)
class Study:
    """A registered study: ``name`` (the CLI's argument), ``title``, one-line ``summary``,
    ``run(options) -> StudyResult``, its place in the report (``order``, then name), and
    optionally ``warm_up(options)``: compiles what ``run`` will compile, in little time once
    compiled, and returns nothing (see the module docstring)."""

    name: str
    title: str
    summary: str
    run: Callable[[StudyOptions], StudyResult]
    order: int = 100
    warm_up: Callable[[StudyOptions], None] | None = None


#: how long ``run_briefly`` runs each case (seconds of simulated time)
BRIEFLY_S = 1.0


def run_briefly(cases: Iterable, seconds: float = BRIEFLY_S) -> None:
    """Simulate the first ``seconds`` of each case (a ``Scenario`` or ``Formation`` with a
    ``duration``), without progress, and drop the results: the compiled kernels of its full
    run end up in the disk cache (a ``Study.warm_up``). A case that is not valid so short
    (a change scheduled later) is left out, as one without a duration."""
    from nonholo.errors import NonholoInputError
    from nonholo.sim.simulator import simulate

    for case in cases:
        if case.duration is None:
            continue
        try:
            simulate(dataclasses.replace(case, duration=min(case.duration, seconds)), progress=False)
        except NonholoInputError:
            continue


def discover() -> dict[str, Study]:
    """Every ``STUDY`` defined by a module of this package, in report order (``order``, name)."""
    import nonholo.studies as package

    found = {}
    for module_info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        study = getattr(importlib.import_module(f"{package.__name__}.{module_info.name}"), "STUDY", None)
        if isinstance(study, Study):
            if study.name in found:
                raise RuntimeError(f"two studies are named {study.name!r}")
            found[study.name] = study
    return dict(sorted(found.items(), key=lambda item: (item[1].order, item[0])))
