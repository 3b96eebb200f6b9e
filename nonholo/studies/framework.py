"""The framework the studies share: number formatting, findings, reference values and our
numbers beside them (agreement), tables (raw records plus the columns that show them, for
the terminal, the report and CSV/JSON) and ``TabulatedStudyResult``, a study result made of
tables, findings and figures.

Terminal output fits ``TERMINAL_WIDTH`` columns: a table shows its ``terminal`` columns, as
many as fit, and says which ones only the report and the CSV carry; findings are wrapped.

>>> fmt(0.000251), fmt(12.345), show(None), show(True)
('2.51e-04', '12.3', '–', 'yes')
>>> print(text_table(["a", "b"], [["x", "1"], ["yy", "22"]]))
a    b
--  --
x    1
yy  22
>>> round(log_ratio(2.0, 1.0), 3), agreement_score([(1.0, 1.0), (10.0, 1.0)]) > 1
(0.693, True)
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nonholo.studies.base import StudyResult
from nonholo.studies.forking import draw_now
from nonholo.studies.report import escape, html_figure, html_list, html_table

TERMINAL_WIDTH = 100


# ------------------------------------------------------------------ numbers

def fmt(value: float) -> str:
    """Three significant digits; scientific below 1e-3 (``2.51e-04``)."""
    return f"{value:.3g}" if value >= 1e-3 or value == 0 else f"{value:.2e}"


def show(value) -> str:
    """Any table value as text: – for None, yes/no, numbers with ``fmt`` (signed)."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            return str(value)
        return f"{value:.2e}" if value != 0 and abs(value) < 1e-3 else fmt(abs(value)) if value >= 0 \
            else "-" + fmt(-value)
    return str(value)


def degrees(value) -> str:
    return "–" if value is None else f"{value:.3f}°"


def log_ratio(ours: float, reference: float) -> float:
    """|ln(ours/reference)|: 0 = equal, ln 10 = a factor of ten (inf if either is ≤ 0)."""
    return abs(math.log(ours / reference)) if ours > 0 and reference > 0 else math.inf


def agreement_score(pairs: Iterable[tuple[float, float]]) -> float:
    """Mean |ln(ours/reference)| over (ours, reference) pairs: 0 = exact, 2.3 = a factor of
    ten on average (spec leader.md §5.3's score)."""
    return float(np.mean([log_ratio(ours, reference) for ours, reference in pairs]))


# ------------------------------------------------------------------ terminal text

def text_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Columns padded to their widest cell (first column left-aligned, the others right)."""
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows)]

    def line(cells):
        return "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    return "\n".join([line(header), line(["-" * w for w in widths])] + [line(r) for r in rows])


def fitted_table(header: Sequence[str], rows: Sequence[Sequence[str]], width: int = TERMINAL_WIDTH,
                 left_out: Sequence[str] = ()) -> str:
    """``text_table`` of as many leading columns as fit in ``width``; a last line names the
    columns left out (``left_out`` and those that did not fit: the report and CSV have them)."""
    keep = len(header)
    while keep > 1 and max(columns(line) for line in text_table(header[:keep], [r[:keep] for r in rows]).splitlines()) \
            > width:
        keep -= 1
    text = text_table(header[:keep], [r[:keep] for r in rows])
    missing = [*header[keep:], *left_out]
    if missing:
        text += "\n" + wrap(f"(also in the report and CSV: {', '.join(missing)})", width)
    return text


def columns(line: str) -> int:
    """The width of a line as counted here: its UTF-8 bytes, an upper bound of its display
    width (so that byte-counting tools such as mawk's ``length`` agree that it fits)."""
    return len(line.encode("utf-8"))


def wrap(text: str, width: int = TERMINAL_WIDTH, first: str = "", rest: str = "") -> str:
    """``text`` wrapped at spaces so that every line fits ``width`` (``columns``); ``first``
    and ``rest`` prefix the first and the following lines."""
    lines, line, empty = [], first, True
    for word in text.split():
        candidate = line + word if empty else f"{line} {word}"
        if columns(candidate) <= width or empty:
            line, empty = candidate, False
        else:
            lines.append(line)
            line = rest + word
        while columns(line) > width:  # a single word longer than the line
            cut = width
            while columns(line[:cut]) > width:
                cut -= 1
            lines.append(line[:cut])
            line = rest + line[cut:]
    lines.append(line)
    return "\n".join(lines)


# ------------------------------------------------------------------ findings and reference values

@dataclass(frozen=True)
class Finding:
    """One generated statement of the "differences" section: ``verdict`` is
    "holds", "fails", "partly" or "note"; ``evidence`` is computed; ``reason`` cites the spec."""

    topic: str
    verdict: str
    evidence: str
    reason: str = ""

    def text(self) -> str:
        reason = f" Why: {self.reason}" if self.reason else ""
        return f"[{self.verdict}] {self.topic}: {self.evidence}{reason}"

    def short(self, width: int = TERMINAL_WIDTH) -> str:
        """The verdict and topic on one line (cut to ``width``), for terminal summaries."""
        line = f"[{self.verdict}] {self.topic}"
        while columns(line) > width:
            line = line[:-2] + "…"
        return line

    def html(self) -> str:
        reason = f" <span class=\"note\">Why: {escape(self.reason)}</span>" if self.reason else ""
        return (f'<span class="{escape(self.verdict)}">{escape(self.verdict)}</span> — <b>{escape(self.topic)}</b>: '
                f"{escape(self.evidence)}{reason}")


def findings_text(findings: Sequence[Finding], width: int = TERMINAL_WIDTH) -> str:
    """The findings as a wrapped bullet list."""
    return "\n".join(wrap(f.text(), width, "- ", "  ") for f in findings)


@dataclass(frozen=True)
class SpecValue:
    """A reference number as the spec prints it (``text``) and the range of our values
    that reproduce it (``low`` ≤ ours ≤ ``high``; wide where the spec says a value is
    integration-sensitive or round-off)."""

    text: str
    low: float
    high: float
    sensitive: bool = False  # integration-sensitive (near-singular passages, sampled peaks)

    @classmethod
    def approx(cls, value: float, rel: float = 0.0, abs_: float = 0.0, text: str | None = None,
               sensitive: bool = False) -> "SpecValue":
        slack = max(abs(value) * rel, abs_)
        return cls(text or f"{value:g}", value - slack, value + slack, sensitive)

    @classmethod
    def below(cls, bound: float, text: str) -> "SpecValue":
        return cls(text, -math.inf, bound)

    def agrees(self, ours: float | None) -> bool:
        return ours is not None and math.isfinite(ours) and self.low <= ours <= self.high


@dataclass(frozen=True)
class Comparison:
    """One of our numbers beside the spec's reference value."""

    case: str
    quantity: str
    ours: float | None
    spec: SpecValue

    @property
    def agrees(self) -> bool:
        return self.spec.agrees(self.ours)

    def record(self) -> dict:
        return {"case": self.case, "quantity": self.quantity, "ours": self.ours, "spec": self.spec.text,
                "range": f"[{self.spec.low:.4g}, {self.spec.high:.4g}]", "sensitive": self.spec.sensitive,
                "agrees": self.agrees}


@dataclass(frozen=True)
class Agreement:
    """How many of a study's comparisons reproduce the spec, robust and integration-sensitive
    values counted apart."""

    robust: tuple[Comparison, ...]
    sensitive: tuple[Comparison, ...]

    @classmethod
    def of(cls, comparisons: Iterable[Comparison]) -> "Agreement":
        comparisons = tuple(comparisons)
        return cls(tuple(c for c in comparisons if not c.spec.sensitive),
                   tuple(c for c in comparisons if c.spec.sensitive))

    @property
    def missing(self) -> list[Comparison]:
        """Every comparison (robust first) whose value is not reproduced."""
        return [c for c in (*self.robust, *self.sensitive) if not c.agrees]

    def counts(self) -> str:
        return (f"{sum(c.agrees for c in self.robust)} of {len(self.robust)} robust and "
                f"{sum(c.agrees for c in self.sensitive)} of {len(self.sensitive)} integration-sensitive values "
                "reproduced")


# ------------------------------------------------------------------ tables

@dataclass(frozen=True)
class Column:
    """A table column: ``label``, the record ``key``, how to show its value, and whether the
    terminal summary shows it (the report and the CSV always do)."""

    label: str
    key: str
    show: Callable[[object], str] = field(default=lambda v: show(v))
    terminal: bool = True


COMPARISON_COLUMNS = (Column("case", "case"), Column("quantity", "quantity"), Column("ours", "ours"),
                      Column("spec", "spec"), Column("accepted range", "range", terminal=False),
                      Column("integration-sensitive", "sensitive", terminal=False), Column("agrees", "agrees"))


@dataclass(frozen=True)
class Table:
    """Records (dicts of raw values, written to CSV/JSON) and the columns that show them."""

    key: str
    caption: str
    columns: Sequence[Column]
    records: Sequence[dict]
    terminal: bool = True  # False: a detail table for the report and CSV only

    @property
    def header(self) -> list[str]:
        return [c.label for c in self.columns]

    def rows(self, columns: Sequence[Column] | None = None) -> list[list[str]]:
        return [[c.show(r.get(c.key)) for c in (columns or self.columns)] for r in self.records]

    def text(self, width: int = TERMINAL_WIDTH) -> str:
        """The caption and the terminal columns, fitted to ``width``."""
        shown = [c for c in self.columns if c.terminal]
        body = fitted_table([c.label for c in shown], self.rows(shown), width,
                            [c.label for c in self.columns if not c.terminal])
        return f"{wrap(self.caption, width)}\n{body}"

    def html(self) -> str:
        return html_table(self.header, self.rows(), self.caption)

    def write_csv(self, path: Path) -> Path:
        keys = list(dict.fromkeys(k for r in self.records for k in r))
        with open(path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, keys)
            writer.writeheader()
            writer.writerows({k: csv_value(r.get(k)) for k in keys} for r in self.records)
        return Path(path)


def json_ready(record: dict) -> dict:
    """A record with NaN/inf as None and numpy floats as floats (strict JSON)."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else
                float(v) if isinstance(v, np.floating) else v) for k, v in record.items()}


def csv_value(value) -> str:
    if value is None:
        return ""
    return f"{value:.10g}" if isinstance(value, (float, np.floating)) else str(value)


# ------------------------------------------------------------------ the tabulated result

class TabulatedStudyResult(StudyResult):
    """A study result made of ``tables()``, ``findings`` and figures (``write_figures``);
    subclasses set ``name``, ``title``, ``runs`` (key → result with ``to_dict()``) and
    implement ``tables``, ``setup_text`` and ``write_figures``."""

    runs: dict
    findings: list[Finding]
    quick: bool

    def tables(self) -> list[Table]:
        raise NotImplementedError

    def setup_text(self) -> str:
        raise NotImplementedError

    def write_figures(self, folder: Path, draw: Callable = draw_now) -> list[tuple[str, str]]:
        """Hand the drawing of each figure into ``folder`` to ``draw``; returns (file name,
        caption) pairs."""
        raise NotImplementedError

    @property
    def ok(self) -> bool:
        """False if any tabulated number is NaN or infinite (a broken simulation)."""
        return all(math.isfinite(v) for table in self.tables() for record in table.records
                   for v in record.values() if isinstance(v, (float, np.floating)))

    def text(self, width: int = TERMINAL_WIDTH) -> str:
        lines = [self.title, "", wrap(self.setup_text(), width), ""]
        for table in self.tables():
            if table.terminal:
                lines += [table.text(width), ""]
            else:
                lines += [wrap(f"In the report and {self.name}-{table.key}.csv only: {table.caption}", width), ""]
        lines += ["Differences from the thesis (the reasons, with citations, are in the report):",
                  findings_text([dataclasses.replace(f, reason="") for f in self.findings], width)]
        return "\n".join(lines)

    def html_section(self, folder: Path, draw: Callable = draw_now) -> str:
        parts = [f"<p>{escape(self.setup_text())}</p>", '<h2 id="' + escape(self.name) + '-differences">Differences '
                 "from the thesis</h2>", html_list(f.html() for f in self.findings),
                 f'<h2 id="{escape(self.name)}-tables">Tables</h2>']
        parts += [table.html() for table in self.tables()]
        parts.append(f'<h2 id="{escape(self.name)}-figures">Figures</h2>')
        import inspect

        # a result written before ``draw`` (``write_figures(self, folder)``) draws its own figures
        drawn_by = "draw" in inspect.signature(self.write_figures).parameters
        for name, caption in (self.write_figures(folder, draw) if drawn_by else self.write_figures(folder)):
            parts.append(html_figure(f"{folder.name}/{name}", caption))
        return "\n".join(parts)

    def to_dict(self) -> dict:
        return {"study": self.name, "quick": self.quick, "elapsed_s": self.elapsed_s, "setup": self.setup_text(),
                "tables": {t.key: {"caption": t.caption, "records": [json_ready(r) for r in t.records]}
                           for t in self.tables()},
                "findings": [dataclasses.asdict(f) for f in self.findings],
                "runs": {key: run.to_dict() for key, run in self.runs.items()}}

    def write_data(self, folder: Path) -> list[Path]:
        paths = [table.write_csv(folder / f"{self.name}-{table.key}.csv") for table in self.tables()]
        data = folder / f"{self.name}.json"
        data.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False))
        return paths + [data]
