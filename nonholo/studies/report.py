"""The report: ``index.html`` with one section per study, plus HTML helpers studies use."""
from __future__ import annotations

import html
import json
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

from nonholo.studies.base import StudyOptions, StudyResult, discover

_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.6em 0 1.4em; font-size: 0.88em; }
th, td { border: 1px solid #bbb; padding: 0.25em 0.55em; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.3em; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; }
.holds { color: #176b1b; font-weight: 600; } .fails { color: #a31515; font-weight: 600; }
.partly { color: #8a5a00; font-weight: 600; } .note { color: #555; font-size: 0.92em; }
"""


def escape(value) -> str:
    return html.escape(str(value), quote=True)


def html_table(header: Sequence[str], rows: Iterable[Sequence], caption: str = "") -> str:
    """A table; cells are escaped text (numbers formatted by the caller)."""
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    body = "\n".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    cap = f"<caption>{escape(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>"


def html_figure(src: str, caption: str) -> str:
    return f'<figure><img src="{escape(src)}" alt="{escape(caption)}"><figcaption>{escape(caption)}</figcaption></figure>'


def html_list(items: Iterable[str]) -> str:
    """A bullet list of already-built HTML fragments."""
    return "<ul>" + "".join(f"<li>{item}</li>" for item in items) + "</ul>"


def write_report(results: Sequence[StudyResult], out_dir: Path) -> Path:
    """Write every study's figures and data under ``out_dir/<study>/`` and the page
    ``out_dir/index.html``; returns the page's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sections, summary = [], {}
    for result in results:
        folder = out_dir / result.name
        folder.mkdir(parents=True, exist_ok=True)
        files = result.write_data(folder)
        links = " · ".join(f'<a href="{escape(f.relative_to(out_dir).as_posix())}">{escape(f.name)}</a>' for f in files)
        sections.append(f'<section id="{escape(result.name)}"><h1>{escape(result.title)}</h1>'
                        f'<p class="note">Data: {links}. Run time {result.elapsed_s:.1f} s.</p>'
                        f"{result.html_section(folder)}</section>")
        summary[result.name] = {"title": result.title, "files": [f.relative_to(out_dir).as_posix() for f in files]}
    contents = html_list(f'<a href="#{escape(r.name)}">{escape(r.title)}</a>' for r in results)
    page = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>nonholo studies</title>"
            f"<style>{_STYLE}</style></head><body><p class=\"note\">nonholo study report, generated "
            f"{escape(time.strftime('%Y-%m-%d %H:%M'))}</p>{contents}\n" + "\n".join(sections) + "</body></html>\n")
    path = out_dir / "index.html"
    path.write_text(page, encoding="utf-8")
    (out_dir / "studies.json").write_text(json.dumps(summary, indent=2))
    return path


def run_studies(names: Sequence[str] | None, options: StudyOptions) -> tuple[list[StudyResult], Path]:
    """Run the named studies (all if ``names`` is empty or None) and write the report."""
    studies = discover()
    chosen = list(names) if names else list(studies)
    unknown = [n for n in chosen if n not in studies]
    if unknown:
        from nonholo.errors import NonholoInputError

        raise NonholoInputError(f"unknown study {unknown[0]!r} (studies: {', '.join(studies)})")
    results = [studies[name].run(options) for name in chosen]
    return results, write_report(results, options.out_dir)
