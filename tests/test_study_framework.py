"""The shared study framework (``nonholo.studies.framework``) and the studies' hygiene."""
import ast
from pathlib import Path

import pytest

from nonholo.studies.framework import (TERMINAL_WIDTH, Agreement, Column, Comparison, Finding, SpecValue, Table,
                                       findings_text, fitted_table)

STUDIES = Path(__file__).resolve().parents[1] / "nonholo" / "studies"


def test_no_private_name_is_imported_across_study_modules():
    offenders = []
    for path in sorted(STUDIES.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("nonholo"):
                offenders += [f"{path.name}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert offenders == []


def test_wide_tables_fit_the_terminal():
    header = [f"column {i}" for i in range(20)]
    rows = [[f"{i * 1.2345:.4g}" for i in range(20)] for _ in range(3)]
    text = fitted_table(header, rows)
    assert max(len(line) for line in text.splitlines()) <= TERMINAL_WIDTH
    assert "column 19" in text.splitlines()[-1] and "column 0" in text.splitlines()[0]


def test_table_text_hides_report_only_columns():
    table = Table("t", "A caption " * 30, [Column("case", "case"), Column("ours", "ours"),
                                           Column("range", "range", terminal=False)],
                  [{"case": "a", "ours": 0.000251, "range": "[0, 1]"}])
    lines = table.text().splitlines()
    assert max(map(len, lines)) <= TERMINAL_WIDTH
    assert "2.51e-04" in table.text() and "range" in lines[-1] and "[0, 1]" not in table.text()


def test_findings_wrap_and_agreement_counts():
    finding = Finding("topic", "holds", "evidence " * 40, "reason " * 20)
    assert max(len(line) for line in findings_text([finding]).splitlines()) <= TERMINAL_WIDTH
    comparisons = [Comparison("c", "q", 1.0, SpecValue.approx(1.0, abs_=0.1)),
                   Comparison("c", "r", 5.0, SpecValue.approx(1.0, abs_=0.1, sensitive=True)),
                   Comparison("c", "s", None, SpecValue.below(1.0, "< 1"))]
    agreement = Agreement.of(comparisons)
    assert agreement.counts() == "1 of 2 robust and 0 of 1 integration-sensitive values reproduced"
    assert [c.quantity for c in agreement.missing] == ["s", "r"]


@pytest.mark.parametrize("module", ["framework", "solver_steps"])
def test_study_modules_live_under_studies(module):
    assert (STUDIES / f"{module}.py").is_file()
    assert not (STUDIES.parent / "sim" / "solver_steps.py").exists()


def test_docstring_examples():
    import doctest

    from nonholo.studies import framework, sweep

    for module in (framework, sweep):
        failures, attempted = doctest.testmod(module)
        assert attempted > 0 and failures == 0


# ------------------------------------------------------------------ the report page

class _Result:
    """A minimal study result for report tests."""

    quick, ok = True, True

    def __init__(self, name, spec_file, body):
        self.name, self.title, self.elapsed_s, self.spec_file, self.body = name, f"Study {name}", 1.5, spec_file, body

    def write_data(self, folder):
        path = folder / f"{self.name}.json"
        path.write_text("{}")
        return [path]

    def html_section(self, folder):
        return self.body


def test_report_contents_citations_and_numbers(tmp_path):
    import re

    from nonholo.studies.citations import ERRATA, SECTIONS
    from nonholo.studies.report import html_table, write_report

    leader = _Result("leader", "leader.md", '<h2 id="leader-tables">Tables</h2><p>see spec §5.3 and errata 20–21; '
                                            "2.51e-04 m</p>" + html_table(["a", "b"], [["x", "2.51e-04"]]))
    formation = _Result("formation", "follower-posture.md",
                        '<h2 id="formation-figures">Figures</h2><p>(errata 15, 18, 19; spec §2.2/§3.2)</p>')
    page = write_report([leader, formation], tmp_path).read_text(encoding="utf-8")
    ids = set(re.findall(r'id="([^"]+)"', page))
    links = re.findall(r'href="#([^"]+)"', page)
    assert {"leader", "leader-tables", "formation", "formation-figures", "appendix"} <= set(links)
    assert set(links) <= ids  # every contents entry and every citation resolves
    for number in (20, 21):
        assert f'href="#erratum-leader-{number}"' in page and ERRATA[("leader.md", number)][0] in page
    for number in (15, 18, 19):
        assert f'id="erratum-follower-posture-{number}"' in page
    for file, key in (("leader.md", "5.3"), ("follower-posture.md", "2.2"), ("follower-posture.md", "3.2")):
        assert SECTIONS[(file, key)][0] in page
    assert re.search(r'<td class="num">(<span class="nb">)?2\.51e-04', page)
    assert '<p>see spec' in page and '<span class="nb">2.51e-04</span> m</p>' in page
    assert "td.num, .nb { white-space: nowrap" in page
    assert page.index('id="leader"') < page.index('id="formation"') < page.index('id="appendix"')


def test_every_citation_in_the_studies_is_explained():
    """Every erratum and specification section that a study's text can cite has an
    appendix entry (the citations are read from the study modules' source)."""
    from nonholo.studies.citations import find_citations, known

    missing = set()
    for module, spec_file in (("leader", "leader.md"), ("formation", "follower-posture.md"),
                              ("posture", "follower-posture.md")):
        text = (STUDIES / f"{module}.py").read_text()
        text = text[text.index('"""', text.index('"""') + 3):]  # the module docstring is not rendered
        missing |= {c for c in find_citations(text, spec_file) if not known(c)}
    assert missing == set()


def test_studies_run_in_report_order():
    from nonholo.studies.report import chosen_studies

    assert [s.name for s in chosen_studies(["posture", "leader", "formation"])] == ["leader", "formation", "posture"]
    assert [s.name for s in chosen_studies(None)][:3] == ["leader", "formation", "posture"]


def test_progress_logs_when_not_a_terminal(monkeypatch):
    import io
    import time

    from nonholo.studies import progress as progress_module
    from nonholo.studies.progress import Progress, mode_for

    stream = io.StringIO()
    assert mode_for(True, stream) == "log" and mode_for(False, stream) == "off"
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    with Progress("study demo", 2, "log", stream=stream, heartbeat=0.5) as progress:
        progress.start("first " + "very long step name " * 8)
        time.sleep(1.3)  # a long step: heartbeat lines while it runs
        progress.done()
        progress.start("second")
        progress.done()
    lines = stream.getvalue().splitlines()
    assert lines[0] == "study demo: started, 2 steps"
    assert any("running: first" in line for line in lines)
    assert lines[-1].startswith("study demo: 2/2 steps, ") and lines[-1].endswith("(done: second)")
    assert all(len(line.encode()) <= 100 for line in lines)


def test_the_report_writer_keeps_no_study_result(tmp_path):
    # nonholo study adds each result as soon as its study finishes and drops it: the writer
    # must not keep it (the leader study's recorded runs are ~300 MB)
    import gc
    import weakref

    from nonholo.studies.report import ReportWriter

    writer = ReportWriter(tmp_path)
    result = _Result("leader", "leader.md", '<h2 id="leader-tables">Tables</h2><p>spec §5.3</p>')
    alive = weakref.ref(result)
    writer.add(result)
    del result
    gc.collect()
    assert alive() is None
    page = writer.finish().read_text(encoding="utf-8")
    assert 'id="leader-tables"' in page and 'id="appendix"' in page


def test_log_axis_labels_are_plain_text_with_the_same_values():
    """The report's log axes are labelled 10⁻⁴, 2×10⁻⁴ … in plain text (``plain_log_labels``),
    the labels matplotlib's mathtext would draw, tick for tick."""
    import matplotlib.pyplot as plt

    from nonholo.studies.plots import PlainLogFormatter, plain_log_labels

    fig, (wide, narrow) = plt.subplots(1, 2)
    wide.semilogy([0, 1], [1e-7, 1e2])
    narrow.set_yscale("log")
    narrow.set_ylim(2e-4, 7e-3)   # within a decade: minor ticks get labels too
    fig.canvas.draw()
    mathtext = [[t.get_text() for t in ax.yaxis.get_ticklabels(minor=minor)] for ax in (wide, narrow)
                for minor in (False, True)]
    plain_log_labels(fig)
    assert isinstance(wide.yaxis.get_major_formatter(), PlainLogFormatter)
    fig.canvas.draw()
    plain = [[t.get_text() for t in ax.yaxis.get_ticklabels(minor=minor)] for ax in (wide, narrow)
             for minor in (False, True)]
    plt.close(fig)
    assert "$\\mathdefault{10^{-4}}$" in mathtext[0] and "10⁻⁴" in plain[0]
    assert any("\\times" in label for label in mathtext[3])   # labelled minor ticks: 2×10⁻³ …
    for before, after in zip(mathtext, plain):
        assert len(before) == len(after)
        for m, p in zip(before, after):
            expected = (m.replace("$\\mathdefault{", "").replace("}$", "").replace("\\times", "×")
                        .replace("^{", "^").replace("}", ""))
            if "^" in expected:
                base, exponent = expected.split("^")
                expected = base + exponent.translate(str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻"))
            assert p == expected


def test_save_figure_writes_other_formats_and_closes_the_figure(tmp_path):
    """Found by review: the PNG compression level must not reach matplotlib's SVG or PDF
    writers (``SweepResult.plot("g.pdf")``), and a figure is closed even if saving fails."""
    import matplotlib.pyplot as plt

    from nonholo.studies.plots import save_figure

    for name in ("f.png", "f.svg", "f.pdf"):
        fig, ax = plt.subplots()
        ax.semilogy([1, 2], [1e-3, 1])
        save_figure(fig, tmp_path / name)
        assert (tmp_path / name).stat().st_size > 0 and not plt.fignum_exists(fig.number)
    fig, _ = plt.subplots()
    with pytest.raises(ValueError):
        save_figure(fig, tmp_path / "f.unknown-format")
    assert not plt.fignum_exists(fig.number)
