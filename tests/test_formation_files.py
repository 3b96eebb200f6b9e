"""Formation/posture scenario files, bad-file errors and ``nonholo run`` output."""
import nonholo as nh
import json
import math

import pytest

from nonholo.cli import main
from nonholo.errors import ScenarioError
from nonholo.formation import Formation
from nonholo.sim.files import parse_scenario

HEAD = """
[simulation]
duration = 5.0
[reference]
kind = "eight"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
"""


def follower(name="f1", leader="leader", extra=""):
    return f"""
[[robots]]
name = "{name}"
formation = "separation-bearing"
leader = "{leader}"
l = 2.0
phi = "pi/3"
{extra}
"""


def test_parses_followers_changes_and_angles():
    text = HEAD + follower(extra='start_relative = [-4, 0, 0]\n[[robots.changes]]\nat = 2\nphi = "4*pi/3"\n'
                                 'direction = "counterclockwise"')
    formation = parse_scenario(text, "f.toml")
    assert isinstance(formation, nh.Scenario) and formation.followers
    f1 = formation.robot("f1")
    assert f1.targets == (2.0, pytest.approx(math.pi / 3)) and f1.start_frame == "leader"
    assert f1.changes[0].targets["phi"] == pytest.approx(4 * math.pi / 3)


@pytest.mark.parametrize("text, field, message", [
    (HEAD + follower(leader="ghost"), "robots[1].leader", "unknown robot 'ghost'"),
    (HEAD + follower(leader="f1"), "robots[1].leader", "cannot follow itself"),
    (HEAD + follower("a", "b") + follower("b", "a"), "robots", "cycle: a -> b -> a"),
    (HEAD + follower(extra="d = 0.0"), "robots[1].d", "castor offset must be > 0"),
    (HEAD.replace('kind = "eight"', 'kind = "eight"') + follower().replace("l = 2.0", "l = -1.0"), "robots[1].l",
     "must be > 0"),
    ("[formation]\npiconet = true\n" + HEAD + "".join(follower(f"f{i}") for i in range(8)), "formation.piconet",
     "at most 7 followers"),
    (HEAD + follower(extra='[[robots.changes]]\nat = 2\nphi = "4*pi/3"'), "robots[1].changes[0].phi", "ambiguous"),
    (HEAD + follower(extra='[[robots.changes]]\nat = 2\nl = 3\nmode = "ramp"'), "robots[1].changes[0].duration",
     "a ramp needs"),
    (HEAD + follower(extra='[[robots.changes]]\nat = 2\nl1 = 3'), "robots[1].changes[0].l1", "not an output"),
    (HEAD + '[[robots]]\nname = "F"\nformation = "separation-separation"\nleaders = ["leader", "leader"]\n'
            'l = [2, 2]\nstart = [0, -2, 0]', "robots[1].leaders", "must differ"),
    (HEAD + '[[robots]]\nname = "F"\nformation = "separation-separation"\nleaders = ["leader"]\nl = [2, 2]',
     "robots[1].leaders", "expected two robot names"),
    ('[simulation]\nduration = 5\n[[robots]]\ngoal = [0, 0, 0]\ncontroller = "polar"\ngains = { k9 = 1 }',
     "robots[0].gains.k9", "unknown gain"),
    ('[[robots]]\ngoal = [0, 0, 0]\ncontroller = "polar"', "simulation.duration", "missing"),
    ('[simulation]\nduration = 5\n[[robots]]\ngoal = [0, 0, 0]\ncontroller = "dynamic-feedback-posture"\n'
     'gains = { xi0 = 0.0 }', "robots[0].gains", "xi0"),
])
def test_bad_files_get_one_line_errors(text, field, message):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "bad.toml")
    error = info.value
    assert error.field == field and message in error.problem
    assert "\n" not in str(error) and str(error).startswith("bad.toml: ")


def test_leader_only_files_still_use_the_core_path():
    from nonholo.sim.scenario import Scenario

    assert isinstance(parse_scenario(HEAD), Scenario)


def test_run_json_formation(capsys, tmp_path):
    assert main(["run", "formation-circle-switch", "--json", "--out", str(tmp_path)]) == 0
    summary = json.loads(capsys.readouterr().out)
    follower = summary["robots"]["follower"]["formation"]
    assert set(follower["l_error"]) == {"mean", "max", "final"} and set(follower["phi_error"]) == {"mean", "max", "final"}
    assert follower["settling"][0]["phi_settling_time"] == pytest.approx(3.92)
    safety = follower["safety"]
    for key in ("min_distance", "time_below_2d", "peak_v", "peak_omega"):
        assert key in safety
    assert summary["safety"]["min_distance"] == pytest.approx(1.01, abs=0.01)
    assert (tmp_path / "formation.gif").stat().st_size > 0 and (tmp_path / "plot.png").exists()


def test_run_json_triangle_and_posture(capsys):
    assert main(["run", "formation-eight-triangle", "--json"]) == 0
    f = json.loads(capsys.readouterr().out)["robots"]["F"]["formation"]
    assert {"l1_error", "l2_error"} <= set(f) and f["safety"]["min_abs_sin_gamma_difference"] == pytest.approx(0.707, abs=1e-3)
    assert main(["run", "posture-dynamic-feedback", "--json"]) == 0
    p = json.loads(capsys.readouterr().out)["robots"]["robot"]["posture"]
    assert p["position_error"]["final"] < 1e-10 and p["heading_error"]["final"] == pytest.approx(math.pi, abs=1e-3)
    assert p["heading_controlled"] is False and "not controlled" in p["note"]
    assert main(["run", "posture-polar"]) == 0
    assert "goal distance final" in capsys.readouterr().out


def test_run_bad_formation_file_exits_2(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(HEAD + follower(leader="ghost"))
    assert main(["run", str(path)]) == 2
    assert "robots[1].leader: unknown robot 'ghost'" in capsys.readouterr().err


def test_animation_frames_are_the_whole_figure_at_each_instant(tmp_path):
    # frames are blitted: the static figure drawn once, the robots drawn again at each frame
    import numpy as np
    from PIL import Image

    from nonholo import examples
    from nonholo.sim.plotting import animate

    result = nh.simulate(nh.load_scenario(examples.resolve("formation-circle-switch")))
    path = animate(result, tmp_path / "a.gif", frames=5, fps=10)
    with Image.open(path) as gif:
        assert gif.n_frames == 5 and gif.info["duration"] == 100
        frames = []
        for i in range(gif.n_frames):
            gif.seek(i)
            frames.append(np.asarray(gif.convert("RGB")).astype(int))
    # the axes, ticks and the reference (static) are in every frame, the robots move
    dark = [(frame.sum(axis=2) < 200).sum() for frame in frames]
    assert min(dark) > 0.5 * max(dark) > 0
    assert all(np.abs(a - b).sum() > 0 for a, b in zip(frames, frames[1:]))
