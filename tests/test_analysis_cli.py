"""`nonholo analyze`: user TOML files, safe expressions, formats and exit codes."""
import argparse
import json

import pytest
import sympy as sp

from nonholo.analysis import ExpressionError, load_system_file, parse_expression
from nonholo.cli import analyze

CHAINED_2_4 = '''
states = ["z1", "z2", "z3", "z4"]
inputs = ["u1", "u2"]
outputs = ["z1", "z4"]
[fields]
u1 = ["1", "0", "z2", "z3"]
u2 = ["0", "1", "0", "0"]
'''


def run(argv, capsys):
    parser = argparse.ArgumentParser(prog="nonholo")
    analyze.register(parser.add_subparsers())
    args = parser.parse_args(argv)
    code = args.handler(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def write(tmp_path, text, name="system.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_json_for_unicycle_has_the_required_keys(capsys):
    code, out, err = run(["analyze", "unicycle", "--format", "json"], capsys)
    assert code == 0 and err == ""
    report = json.loads(out)
    assert report["n"] == 3
    assert report["accessibility_rank"] == 3 and report["accessibility_degree"] == 2
    assert report["involutive"] is False and report["nonholonomic"] is True
    assert report["linear_controllability_rank_at_point"] == 2
    assert report["linear_controllability_rank_along_reference"] == 3
    assert report["observability_rank"] == 3
    assert report["observability"]["rank_lost_where"] == "v = 0"
    assert report["brackets"]["[g1, g2]"] == ["sin(theta)", "-cos(theta)", "0"]
    assert report["body_frame"]["controllability"]["rank_lost_where"] == "omega_d = 0 and v_d = 0"
    assert [c["verified"] for c in report["chained_forms"]] == [True, True]
    assert report["flat"] is True


def test_at_point_values_and_json_alias(capsys):
    code, out, _ = run(["analyze", "unicycle", "--json", "--at", "theta=pi/2, v=0"], capsys)
    report = json.loads(out)
    assert code == 0
    assert report["linearization_point"] == {"x": "x_e", "y": "y_e", "theta": "pi/2"}
    assert report["observability_rank_at_point"] == 2  # v = 0: the heading is not observable
    assert report["accessibility_rank_at_point"] == 3


def test_text_report_states_and_explains(capsys):
    code, out, _ = run(["analyze", "unicycle"], capsys)
    assert code == 0
    assert "is not involutive" in out and "nonholonomic" in out
    assert "Rank 3 = n is reached at degree 2" in out
    assert "C_M has generic rank 2 < n = 3." in out and "Brockett" in out
    assert "wherever v ≠ 0" in out


@pytest.mark.parametrize("fmt, marker", [("markdown", "## Accessibility"),
                                         ("latex", r"\begin{document}")])
def test_markdown_and_latex(capsys, fmt, marker):
    code, out, _ = run(["analyze", "unicycle", "--format", fmt], capsys)
    assert code == 0 and marker in out
    assert r"\sin{\left(\theta \right)}" in out


def test_list_builtins(capsys):
    code, out, _ = run(["analyze", "--list"], capsys)
    assert code == 0
    assert [line.split()[0] for line in out.splitlines()] == [
        "unicycle", "separation-bearing", "separation-separation", "car", "unicycle-trailer"]


def test_user_file_chained_form(tmp_path, capsys):
    code, out, _ = run(["analyze", write(tmp_path, CHAINED_2_4), "--json", "--depth", "4"],
                       capsys)
    report = json.loads(out)
    assert code == 0
    assert report["accessibility_ranks"] == [2, 3, 4, 4] and report["accessibility_degree"] == 3
    assert report["nilpotency_step"] == 3
    assert report["brackets"]["[g1, g2]"] == ["0", "0", "-1", "0"]


def test_user_file_holonomic(tmp_path, capsys):
    text = 'states = ["x", "y", "z"]\ninputs = ["a", "b"]\n[fields]\na = [1, 0, 0]\nb = [0, 1, 0]\n'
    code, out, _ = run(["analyze", write(tmp_path, text), "--json"], capsys)
    report = json.loads(out)
    assert code == 0
    assert report["involutive"] is True and report["nonholonomic"] is False
    assert report["accessibility_rank"] == 2 and report["accessibility_degree"] is None
    assert report["observability_rank"] is None


def test_parameters_are_exact_and_power_caret(tmp_path):
    text = CHAINED_2_4.replace('u2 = ["0", "1", "0", "0"]', 'u2 = ["0", "L^2", "0", "0"]') \
        + "[parameters]\nL = 0.5\n"
    system = load_system_file(write(tmp_path, text))
    assert system.fields[1] == sp.Matrix([0, sp.Rational(1, 4), 0, 0])
    assert system.parameters == {"L": sp.Rational(1, 2)}


@pytest.mark.parametrize("text, message", [
    (CHAINED_2_4.replace('"z2", "z3"]', '"q", "z3"]'),
     "fields.u1[3]: unknown symbol 'q' in 'q'"),
    (CHAINED_2_4.replace('u2 = ["0", "1", "0", "0"]', 'u2 = ["0", "1", "0"]'),
     "fields.u2: has 3 components but there are 4 states (z1, z2, z3, z4)"),
    (CHAINED_2_4 + '[parameters]\nL = "abc"\n',
     "parameters.L: expected a finite number, got str 'abc'"),
    (CHAINED_2_4.replace('"z2", "z3"]', '"__import__(\'os\')", "z3"]'),
     "fields.u1[3]: unknown function '__import__'"),
    (CHAINED_2_4.replace('u2 = ["0", "1", "0", "0"]', ''),
     "fields: no vector field for input 'u2'"),
    ("states = [\n", "not valid TOML"),
])
def test_user_file_errors_are_one_line_and_exit_2(tmp_path, capsys, text, message):
    path = write(tmp_path, text)
    code, out, err = run(["analyze", path], capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"nonholo analyze: error: {path}: ")
    assert message in err


@pytest.mark.parametrize("argv, message", [
    (["analyze", "bicycle"], "'bicycle' is neither a built-in system"),
    (["analyze", "unicycle", "--at", "q=1"], "--at: unknown name 'q'"),
    (["analyze", "unicycle", "--at", "theta"], "--at: expected name=value"),
    (["analyze", "unicycle", "--at", "theta=x"], "--at theta: unknown symbol 'x'"),
    (["analyze", "unicycle", "--depth", "0"], "--depth must be between 1 and 8"),
    (["analyze"], "give a SYSTEM name or FILE"),
])
def test_bad_command_line_exit_2(capsys, argv, message):
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and message in err


def test_parse_expression_whitelist():
    x = sp.Symbol("x")
    assert parse_expression("-x^2 + 3*sin(x)/2", {"x": x}) == -x ** 2 + 3 * sp.sin(x) / 2
    assert parse_expression("atan2(1, 2) + pi", {}) == sp.atan2(1, 2) + sp.pi
    for text in ("x.real", "[x]", "lambda: 0", "x if x else x", "sin(x, x)", "1j", "x == 1"):
        with pytest.raises(ExpressionError):
            parse_expression(text, {"x": x})


def test_car_report(capsys):
    code, out, _ = run(["analyze", "car", "--json"], capsys)
    report = json.loads(out)
    assert code == 0
    assert report["n"] == 4 and report["accessibility_rank"] == 4
    assert report["accessibility_degree"] == 3
    assert report["brackets"]["[g1, g2]"] == ["0", "0", "-1/(L*cos(phi)**2)", "0"]
    assert report["observability"]["rank_lost_where"] == "v = 0"
    assert report["linear_controllability_rank_at_point"] == 2


def test_depth_1_still_tests_involutivity(capsys):
    code, out, _ = run(["analyze", "unicycle", "--json", "--depth", "1"], capsys)
    report = json.loads(out)
    assert code == 0
    assert report["involutive"] is False and report["brackets"] == {}
    assert report["accessibility_ranks"] == [2] and report["accessibility_degree"] is None
