"""`nonholo study`, `nonholo sweep`: exit codes and files."""
import json

from nonholo.cli import main


def test_study_quick_writes_report(tmp_path, capsys):
    assert main(["study", "leader", "--quick", "--quiet", "--sampling", "uniform", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "index.html").stat().st_size > 0
    assert "report:" in capsys.readouterr().out
    data = json.loads((tmp_path / "leader" / "leader.json").read_text())
    assert data["quick"] is True and data["cells"][0]["solver_steps"] is None


def test_study_all_runs_every_registered_study(tmp_path, capsys, monkeypatch):
    import nonholo.studies.report as report

    added = []

    class Writer:   # the report writer sees every study's result as soon as it finishes
        def __init__(self, out, options=None):
            self.out = out

        def add(self, result):
            added.append(result.name)
            return 0.0

        def finish(self):
            return self.out / "index.html"

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            pass

    monkeypatch.setattr(report, "ReportWriter", Writer)
    from nonholo.studies import base

    fake = base.Study("fake", "Fake", "for the test", lambda options: FakeResult())
    monkeypatch.setattr(report, "discover", lambda: {"fake": fake})
    assert main(["study", "--quiet", "--out", str(tmp_path)]) == 0
    assert added == ["fake"]


class FakeResult:
    name, title, elapsed_s, ok = "fake", "Fake", 0.0, True

    def text(self):
        return "fake"


def test_study_bad_input(capsys):
    assert main(["study", "no-such-study", "--quiet"]) == 2
    assert "unknown study" in capsys.readouterr().err


def test_sweep_cli(tmp_path, capsys):
    code = main(["sweep", "test2-line", "--robot", "kanayama", "--gain", "kx=1:9:3", "--steps", "2000",
                 "--out", str(tmp_path), "--json", "--quiet"])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["axes"] == {"kx": [1.0, 5.0, 9.0]} and data["trend"]["word"]
    for name in ("sweep.csv", "sweep.json", "sweep.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_sweep_cli_bad_input(capsys):
    assert main(["sweep", "test1-eight", "--gain", "zeta=0.1:0.9"]) == 2
    assert "NAME=START:STOP:COUNT" in capsys.readouterr().err
    assert main(["sweep", "test1-eight", "--gain", "zeta=0.1:0.9:3"]) == 2
    assert "--robot" in capsys.readouterr().err
    assert main(["sweep", "test1-eight", "--robot", "nonlinear", "--gain", "zeta=0.5:2:3"]) == 2
