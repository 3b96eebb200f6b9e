"""The report: ``index.html`` with one section per study (in the studies' ``order``: the
Chapter 5 leader tables first), a table of contents with sub-navigation, an appendix that
explains every specification section and erratum the report cites, plus the HTML helpers
the studies use.

Numbers are never broken across lines: numeric table cells and scientific numbers in the
text are kept on one line (CSS ``white-space: nowrap``).
"""
from __future__ import annotations

import functools
import html
import json
import re
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

from nonholo.studies.base import StudyOptions, StudyResult, discover
from nonholo.studies.forking import ForkedCall
from nonholo.studies.progress import Progress

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 0; color: #222; line-height: 1.45; }
nav#toc { position: fixed; top: 0; left: 0; bottom: 0; width: 14.5rem; overflow-y: auto; box-sizing: border-box;
          padding: 1rem 0.8rem; background: #f5f6f7; border-right: 1px solid #d8d8d8; font-size: 0.88em; }
nav#toc h2 { font-size: 1.05em; margin: 0 0 0.5em; }
nav#toc ol { padding-left: 1.2em; margin: 0.2em 0; } nav#toc li { margin: 0.15em 0; }
nav#toc ol ol { font-size: 0.95em; list-style: lower-alpha; }
main { margin-left: 14.5rem; max-width: 1200px; padding: 0.5rem 1.2rem 4rem; }
@media (max-width: 1000px) { nav#toc { position: static; width: auto; border: 0; } main { margin-left: 0; } }
h1 { font-size: 1.6em; border-bottom: 2px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
h2 { font-size: 1.25em; margin-top: 1.4em; } h1, h2, h3, dt, tr { scroll-margin-top: 0.5em; }
.scroll { overflow-x: auto; margin: 0.6em 0 1.4em; }
table { border-collapse: collapse; font-size: 0.82em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.42em; text-align: right; vertical-align: top; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; } td.text { text-align: left; }
th.group { text-align: center; background: #e2e6ea; } td:first-child { white-space: nowrap; }
td.num, .nb { white-space: nowrap; font-variant-numeric: tabular-nums; } td.nw { white-space: nowrap; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.3em; max-width: 60em; }
figure { margin: 1em 0 1.6em; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; max-width: 60em; }
li { margin: 0.35em 0; }
.holds { color: #176b1b; font-weight: 600; } .fails { color: #a31515; font-weight: 600; }
.partly { color: #8a5a00; font-weight: 600; } .note { color: #555; font-size: 0.92em; }
a.cite { text-decoration: none; border-bottom: 1px dotted #36c; }
dl.cites dt { font-weight: 600; margin-top: 0.6em; } dl.cites dd { margin-left: 1.2em; max-width: 60em; }
table.errata td, table.errata th { text-align: left; } table.errata td.num { text-align: right; }
"""

# A cell that is a number (with optional sign, exponent, unit or ratio) is kept on one line.
_NUMERIC = re.compile(r"^[−–+-]?(\d[\d.,]*(e[−+-]?\d+)?|inf|nan)\s?(%|°|×|s|m|m/s|rad/s)?$|^[–-]$|^\d+/\d+$",
                      re.IGNORECASE)
SHORT_CELL = 16  # characters: shorter text cells are never wrapped
_SCIENTIFIC = re.compile(r"(?<![\w.])([−-]?\d+(?:\.\d+)?(?:e|×10\^?)[−+-]?\d+)")


def escape(value) -> str:
    return html.escape(str(value), quote=True)


def numeric(text: str) -> bool:
    """Whether a table cell's text is a number (kept on one line in the report)."""
    return bool(_NUMERIC.match(text.strip()))


def cell_class(text: str) -> str:
    """"num" for a number (right-aligned, one line), "text nw" for a short text such as a
    point "(−10, 10)" (kept on one line), "text" otherwise."""
    if numeric(text):
        return "num"
    return "text nw" if len(text) <= SHORT_CELL else "text"


def html_table(header: Sequence[str], rows: Iterable[Sequence], caption: str = "",
               groups: Sequence[tuple[str, int]] | None = None) -> str:
    """A table; cells are escaped text (numbers formatted by the caller; numeric cells get
    ``class="num"``: never broken across lines). ``groups``: (label, columns spanned) of an
    extra header row above ``header``. Wide tables scroll sideways."""
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    if groups:
        top = "".join(f'<th colspan="{span}" class="group">{escape(label)}</th>' for label, span in groups)
        head = f"<tr>{top}</tr><tr>{head}</tr>"
    else:
        head = f"<tr>{head}</tr>"
    body = "\n".join("<tr>" + "".join(f'<td class="{cell_class(str(c))}">{escape(c)}</td>' for c in row) + "</tr>"
                     for row in rows)
    cap = f"<caption>{escape(caption)}</caption>" if caption else ""
    return f'<div class="scroll"><table>{cap}<thead>{head}</thead><tbody>\n{body}\n</tbody></table></div>'


def html_figure(src: str, caption: str) -> str:
    return f'<figure><img src="{escape(src)}" alt="{escape(caption)}"><figcaption>{escape(caption)}</figcaption></figure>'


def html_list(items: Iterable[str]) -> str:
    """A bullet list of already-built HTML fragments."""
    return "<ul>" + "".join(f"<li>{item}</li>" for item in items) + "</ul>"


def decorate(fragment: str, spec_file: str) -> str:
    """Keep scientific numbers in the text on one line and link citations to the appendix."""
    from nonholo.studies.citations import link_citations

    parts = re.split(r"(<[^>]+>)", fragment)
    for i, part in enumerate(parts):
        if part and not part.startswith("<"):
            parts[i] = _SCIENTIFIC.sub(r'<span class="nb">\1</span>', part)
    return link_citations("".join(parts), spec_file)


def _contents(section_id: str, title: str, fragment: str) -> str:
    """A contents entry for a section and its ``<h2 id=…>`` sub-sections."""
    subs = re.findall(r'<h2 id="([^"]+)">(.*?)</h2>', fragment)
    inner = "".join(f'<li><a href="#{i}">{re.sub(r"<[^>]+>", "", t)}</a></li>' for i, t in subs)
    return f'<li><a href="#{escape(section_id)}">{escape(title)}</a>' + (f"<ol>{inner}</ol>" if inner else "") + "</li>"


class ReportWriter:
    """The report, written one study at a time: ``add`` writes a study's data files under
    ``out_dir/<study>/``, keeps its section of the page and starts drawing its figures (in
    forked processes while the next study runs, ``nonholo.studies.forking``); ``finish``
    waits for the figures, writes ``out_dir/index.html`` (contents, one section per study,
    appendix, run times) and ``studies.json`` and returns the page's path; ``close`` (or the
    end of a ``with`` block) stops any drawing still running. The writer keeps no study
    result: a caller that adds each result as soon as its study finishes can let its arrays
    go before the next study runs (``nonholo study`` does; the leader study's recorded runs are
    ~300 MB; a drawing process keeps its own view of them until its figures are drawn)."""

    def __init__(self, out_dir: Path, options: StudyOptions | None = None):
        from nonholo.studies.forking import Drawing

        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.options = options
        self.sections, self.contents, self.summary, self.citations = [], [], {}, set()
        self.quick = False
        self.drawing = Drawing(options.processes if options is not None else 0)

    def _progress(self, label: str, total: int, unit: str):
        if self.options is None or total == 0:
            return Progress(label, total, "off")
        return self.options.progress_for(label, total, unit)

    def add(self, result: StudyResult) -> float:
        """Write ``result``'s data files and section and start drawing its figures; returns the
        seconds it took this process (the figures may still be drawing: ``finish``)."""
        import matplotlib

        from nonholo.studies.citations import find_citations
        from nonholo.studies.plots import FIGURE_STYLE

        out_dir = self.out_dir
        started = time.perf_counter()
        with self._progress(f"report {result.name}", 1, "section") as progress:
            progress.start(f"{result.name}: data and page")
            folder = out_dir / result.name
            folder.mkdir(parents=True, exist_ok=True)
            with matplotlib.rc_context(FIGURE_STYLE):
                files = result.write_data(folder)
                body = section_html(result, folder, self.drawing)
            spec_file = getattr(result, "spec_file", "leader.md")
            self.citations |= find_citations(re.sub(r"<[^>]+>", "", html.unescape(body)), spec_file)
            body = decorate(body, spec_file)
            progress.done()
        # the figures start once the progress line is closed: no thread of this process
        # writes to the terminal while it forks (a child must not inherit a held stream lock)
        figures = len(self.drawing.queued)
        here = self.drawing.processes == 0 and figures > 0   # drawn now, in this process: show them
        with self._progress(f"figures {result.name}", figures if here else 0, "figures") as progress, \
                matplotlib.rc_context(FIGURE_STYLE):
            self.drawing.start(result.name, progress if here else None)
        links = " · ".join(f'<a href="{escape(f.relative_to(out_dir).as_posix())}">{escape(f.name)}</a>'
                           for f in files)
        self.sections.append((result.name, result.title, result.elapsed_s, links, body))
        self.contents.append(_contents(result.name, result.title, body))
        self.summary[result.name] = {"title": result.title, "elapsed_s": result.elapsed_s, "report_s": None,
                                     "figures": figures, "files": [f.relative_to(out_dir).as_posix() for f in files]}
        self.quick = self.quick or getattr(result, "quick", False)
        return time.perf_counter() - started

    def finish(self) -> Path:
        """Wait for the figures, write the page and ``studies.json``; returns the page's path."""
        from nonholo.studies.citations import appendix_html

        pending = self.drawing.pending()
        with self._progress("report figures", pending, "figures") as progress:
            drawn = self.drawing.finish(progress if pending else None)
        sections = []
        for name, title, elapsed_s, links, body in self.sections:
            seconds = drawn.get(name, {}).get("seconds", 0.0)
            self.summary[name]["report_s"] = round(seconds, 3)
            figures = self.summary[name]["figures"]
            drawing = f", its {figures} figures {seconds:.1f} s" if figures else ""
            sections.append(f'<section id="{escape(name)}"><h1>{escape(title)}</h1><p class="note">Data: {links}. '
                            f"Simulations and statistics took {elapsed_s:.1f} s (wall time){drawing}.</p>{body}"
                            "</section>")
        appendix = appendix_html(self.citations)
        sections.append(f'<section id="appendix"><h1>Appendix: the specification sections and errata '
                        f"cited</h1>{appendix}</section>")
        contents = [*self.contents, _contents("appendix", "Appendix: specification sections and errata cited", "")]
        rows = "".join(f'<tr><td class="text"><a href="#{escape(name)}">{escape(name)}</a></td>'
                       f'<td class="num">{entry["elapsed_s"]:.1f} s</td>'
                       f'<td class="num">{entry["report_s"]:.1f} s</td></tr>' for name, entry in self.summary.items())
        processes = self.drawing.processes
        drawn_where = (f" (the figures drawn in {processes} other process{'es' if processes > 1 else ''} while the "
                       "next study runs)" if processes else "")
        header = ('<header><h1 style="margin-top:0.6em">nonholo study report</h1>'
                  f'<p class="note">Generated {escape(time.strftime("%Y-%m-%d %H:%M"))} by <code>nonholo study</code>'
                  + (" in QUICK MODE (coarser grids: not the canonical numbers)" if self.quick else "")
                  + ". Each section gives the differences from the thesis first (verdicts computed from the numbers: "
                  '<span class="holds">holds</span>, <span class="partly">partly</span>, <span class="fails">fails</span>, '
                  "note), then the tables and the figures. Citations such as “spec §5.3” or “erratum 19” link to the "
                  "appendix, which explains them.</p>"
                  f'<div class="scroll"><table><caption>Wall times{drawn_where}</caption><thead><tr><th>study</th>'
                  f"<th>simulations and statistics</th><th>figures</th></tr></thead><tbody>{rows}"
                  "</tbody></table></div></header>")
        nav = f'<nav id="toc"><h2>Contents</h2><ol>{"".join(contents)}</ol></nav>'
        page = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>nonholo studies</title>"
                f"<style>{_STYLE}</style></head><body>{nav}<main>{header}\n" + "\n".join(sections)
                + "</main></body></html>\n")
        path = self.out_dir / "index.html"
        path.write_text(page, encoding="utf-8")
        (self.out_dir / "studies.json").write_text(json.dumps(self.summary, indent=2))
        return path

    def close(self) -> None:
        """Stop and reap any figure drawing still running."""
        self.drawing.close()

    def __enter__(self) -> "ReportWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_report(results: Sequence[StudyResult], out_dir: Path, options: StudyOptions | None = None) -> Path:
    """Write every study's figures and data under ``out_dir/<study>/`` and the page
    ``out_dir/index.html`` (``ReportWriter``); returns the page's path. Progress per study
    section if ``options.progress``."""
    with ReportWriter(out_dir, options) as writer:
        for result in results:
            writer.add(result)
        return writer.finish()


def section_html(result: StudyResult, folder: Path, draw) -> str:
    """``result``'s section of the page, its figures handed to ``draw`` (a study whose
    ``html_section`` takes no ``draw`` draws them itself, at once)."""
    import inspect

    if "draw" in inspect.signature(result.html_section).parameters:
        return result.html_section(folder, draw=draw)
    return result.html_section(folder)


def chosen_studies(names: Sequence[str] | None) -> list:
    """The named studies (all if ``names`` is empty or None), in report order."""
    studies = discover()
    unknown = [n for n in names or () if n not in studies]
    if unknown:
        from nonholo.errors import NonholoInputError

        raise NonholoInputError(f"unknown study {unknown[0]!r} (studies: {', '.join(studies)})")
    chosen = list(dict.fromkeys(names)) if names else list(studies)
    return sorted((studies[name] for name in chosen), key=lambda s: (s.order, s.name))


#: the compiling-ahead child's niceness: it takes what the studies' own processes leave
AHEAD_NICE = 10


def each_result(names: Sequence[str] | None, options: StudyOptions) -> Iterator[StudyResult]:
    """Run the named studies in report order, yielding each result as soon as its study
    finishes (and keeping none). With ``options.processes``, a child forked at the start
    runs the later studies' ``warm_up``s at a lower priority (``AHEAD_NICE``): on a first run
    their kernels compile while the first study runs, into the disk cache that the later
    studies then load from (if a study gets there first, it compiles for itself, as without
    the child). The child's failures are its own; it is stopped when the studies end."""
    studies = chosen_studies(names)
    ahead = [study.warm_up for study in studies[1:] if study.warm_up is not None]
    with ForkedCall(functools.partial(_warm_up, ahead, options), options.processes if ahead else 0,
                    "compile-ahead", nice=AHEAD_NICE):
        for study in studies:
            yield study.run(options)


def _warm_up(calls: Sequence[Callable[[StudyOptions], None]], options: StudyOptions) -> None:
    """Every ``calls(options)`` in order, one's failure not stopping the next."""
    for call in calls:
        try:
            call(options)
        except Exception:  # noqa: BLE001 (the study itself will meet it, and report it)
            continue


def run_studies(names: Sequence[str] | None, options: StudyOptions,
                on_result: Callable[[StudyResult], None] | None = None) -> tuple[list[StudyResult], Path]:
    """Run the named studies (all if ``names`` is empty or None) and write the report;
    ``on_result`` sees each result as soon as its study finishes. ``nonholo study`` instead
    writes each section as its study ends and keeps no result (``ReportWriter``)."""
    results = []
    for result in each_result(names, options):
        results.append(result)
        if on_result is not None:
            on_result(result)
    return results, write_report(results, options.out_dir, options)
