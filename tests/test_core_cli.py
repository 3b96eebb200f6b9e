import json
import subprocess
import sys

import pytest

from nonholo.cli import main


def run_cli(*args):
    proc = subprocess.run([sys.executable, "-m", "nonholo", *args], capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


def write(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


GOOD = """
[simulation]
duration = 20.0
dt = 0.01
[reference]
kind = "expression"
x = "6*sin(t/15 + 0.3) + 0.2*t"
y = "4*sin(t/10)"
[[robots]]
name = "leader"
start = [0.0, 0.5, 0.0]
controller = "dynamic-feedback"
gains = { kp = 1.0, kd = 0.7 }
"""


def test_run_json_prints_exactly_one_object(tmp_path, capsys):
    assert main(["run", write(tmp_path, GOOD), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    error = data["robots"]["leader"]["error"]
    assert set(error) == {"mean", "std", "var", "rms", "max", "final"}
    assert error["var"] == pytest.approx(error["std"] ** 2)


def test_run_writes_plot_and_output_folder(tmp_path, capsys):
    plot = tmp_path / "fig.png"
    assert main(["run", write(tmp_path, GOOD), "--plot", str(plot), "--out", str(tmp_path / "out")]) == 0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 20_000
    out = tmp_path / "out"
    assert json.loads((out / "result.json").read_text())["robots"]["leader"]["controller"] == "dynamic-feedback"
    lines = (out / "trajectories.csv").read_text().splitlines()
    assert lines[0].startswith("t_s,robot,role,x_m,y_m,theta_rad")   # tidy: one row per robot and sample, units
    assert lines[1].startswith("0,leader,tracking,0,0.5,0,")
    assert "leader" in capsys.readouterr().out


def test_terminal_summary_fits_100_columns():
    """Long scenario names, tiny peaks and long notes wrap or shrink instead of overflowing."""
    from nonholo.cli.run import format_summary

    robot = {"role": "tracking", "controller": "dynamic-feedback", "control": {"peak_v": 0.559, "peak_omega": 0.000757},
             "error": {"mean": 3.5e-06, "max": 1e-05, "final": 1e-05},
             "events": {"saturated_v_samples": 0, "saturated_omega_samples": 0, "singular_samples": 0}}
    summary = {"scenario": "a-rather-long-scenario-name-" * 3, "reference": {"kind": "eight"},
               "simulation": {"duration": 251.327, "steps": 25133, "dt": 0.01, "method": "rk4", "max_substeps": 1,
                              "elapsed_s": 3.3},
               "robots": {"leader": robot}, "safety": {}}
    text = format_summary(summary)
    assert max(len(line) for line in text.splitlines()) <= 100
    assert "0.000757" not in text and "0.00076" in text   # the peak shrinks to the column's 7 characters


def test_bundled_example_runs_by_name(capsys):
    assert main(["run", "expression", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["robots"]["leader"]["events"]["saturated_v_samples"] > 0


BAD = [
    (GOOD.replace('controller = "dynamic-feedback"', 'controller = "pid"'),
     "robots[0].controller: unknown value 'pid' (valid: approximate-linearization, nonlinear"),
    (GOOD.replace('controller = "dynamic-feedback"', 'controller = ["polar"]'),
     "robots[0].controller: expected a string, got list ['polar']"),
    (GOOD.replace('controller = "dynamic-feedback"', 'controller = "polar"').replace("gains = { kp = 1.0, kd = 0.7 }", ""),
     "robots[0].goal: missing: the posture law polar stabilises to a goal"),
    (GOOD.replace('controller = "dynamic-feedback"', 'controller = "kanayama"\ngoal = [0, 0, 0]')
     .replace("gains = { kp = 1.0, kd = 0.7 }", ""),
     "robots[0].controller: kanayama is a tracking law; a robot with a goal needs a posture law"),
    (GOOD.replace("kp = 1.0", "kq = 1.0"),
     "robots[0].gains.kq: unknown gain for dynamic-feedback (gains: kp1, kp2, kd1, kd2, xi_min, kp, kd, xi0)"),
    (GOOD.replace("dt = 0.01", "dt = 0"), "simulation.dt: expected a positive number, got 0"),
    (GOOD.replace("dt = 0.01", 'dt = "fast"'), "simulation.dt: expected a finite number, got str 'fast'"),
    (GOOD.replace("start = [0.0, 0.5, 0.0]", "start = [0.0, 0.5]"), "robots[0].start: expected a list of 3 finite numbers"),
    (GOOD.replace('x = "6*sin(t/15 + 0.3) + 0.2*t"', 'x = "__import__(1)"'), "reference.x: unknown function '__import__'"),
    (GOOD.replace('kind = "expression"', 'kind = "spiral"'), "reference.kind: unknown value 'spiral'"),
    (GOOD.replace("kp = 1.0", "kp = -1.0"), "robots[0].gains: gain 'kp1' of dynamic-feedback must be > 0, got -1"),
    (GOOD.replace("[simulation]", "[simulation]\nspeed = 3"), "simulation.speed: unknown field"),
    (GOOD + "\n[[robots]]\nname = \"leader\"\n", "robots[1].name: 'leader' is already the name of robots[0]: robot "
                                                   "names must be unique"),
    (GOOD.replace("start = [0.0, 0.5, 0.0]", "start = [1e300, 0.5, 0.0]"),
     "robots[0].start: x and y must be within ±1e+07 m and theta within ±1e+06 rad"),
    ("[reference\n", "not valid TOML"),
    (GOOD.replace('controller = "dynamic-feedback"', 'controller = "kanayama"').replace("gains = { kp = 1.0, kd = 0.7 }", "")
         .replace('x = "6*sin(t/15 + 0.3) + 0.2*t"', 'x = "(t-3)^3"').replace('y = "4*sin(t/10)"', 'y = "(t-3)^2"'),
     "vanishes at t = 3 s"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_scenarios_get_one_line_errors_and_exit_2(tmp_path, capsys, text, message):
    path = write(tmp_path, text)
    assert main(["run", path]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert "Traceback" not in err


@pytest.mark.parametrize("option, message", [
    (["--plot", "p.txt"], "--plot p.txt: unknown image format 'txt' (name it .png, .pdf, .svg"),
    (["--plot", "p"], "--plot p: no format"),
    (["--animate", "a.png"], "--animate a.png: name it .gif (or .mp4, with ffmpeg)")])
def test_an_output_name_of_no_known_format_is_refused_before_the_run(tmp_path, capsys, option, message):
    assert main(["run", "test2-line", "--quiet", "--json", *[str(tmp_path / o) if "." in o or o == "p" else o
                                                              for o in option]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message.split(": ", 1)[1] in err and "Traceback" not in err


def test_missing_file_and_help():
    code, _, err = run_cli("run", "no-such-file.toml")
    assert code == 2 and "no-such-file.toml: cannot read" in err and "Traceback" not in err
    code, out, _ = run_cli("run", "--help")
    assert code == 0 and "test1-eight" in out


def test_summary_lines_wrap_within_100_columns_never_between_a_number_and_its_unit():
    from nonholo.cli import wrap

    for pad in range(60, 100):
        line = "x" * pad + " run in 0.46 s, delay 0.15 s + jitter up to 0 s; beyond 0.1 s at 3.2 m/s, 7 steps"
        wrapped = wrap(line).split("\n")
        assert all(len(part) <= 100 for part in wrapped)
        assert " ".join(part.strip() for part in wrapped) == line
        assert not any(part.rstrip()[-1:].isdigit() and nxt.lstrip()[:1] in "smr" and nxt.lstrip().split()[0] in
                       ("s", "s,", "s;", "m/s,", "steps") for part, nxt in zip(wrapped, wrapped[1:]))
