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
