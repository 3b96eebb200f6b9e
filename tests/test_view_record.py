"""MCAP recordings: a run written with --record reads back, with the mcap library's own reader,
to the run's numbers; the pose channels use Foxglove's well-known schemas."""
import dataclasses
import json
import math

import numpy as np
import pytest

pytest.importorskip("mcap", reason="the view extra (mcap) is not installed")

from mcap.reader import make_reader  # noqa: E402

from nonholo import examples  # noqa: E402
from nonholo.cli import main  # noqa: E402
from nonholo.errors import NonholoInputError  # noqa: E402
from nonholo.sim.files import load_scenario  # noqa: E402
from nonholo.sim.simulator import simulate  # noqa: E402
from nonholo.view.data import from_result  # noqa: E402
from nonholo.view.record import read_recording, write_recording  # noqa: E402


def wrapped(a):
    return np.angle(np.exp(1j * np.asarray(a)))


@pytest.fixture(scope="module")
def triangle():
    scenario = load_scenario(examples.resolve("formation-eight-triangle"))
    return simulate(dataclasses.replace(scenario, duration=4.0), progress=False)


def test_round_trip_equals_the_result(triangle, tmp_path):
    path = write_recording(from_result(triangle), tmp_path / "run.mcap")
    back = read_recording(path)
    assert back.names == list(triangle.names)
    assert np.array_equal(back.t, triangle.t) or np.abs(back.t - triangle.t).max() < 1e-9
    for i, name in enumerate(triangle.names):
        assert np.abs(back.pose[:, i, 0] - triangle.x[i]).max() < 1e-12
        assert np.abs(back.pose[:, i, 1] - triangle.y[i]).max() < 1e-12
        assert np.abs(wrapped(back.pose[:, i, 2] - triangle.theta[i])).max() < 1e-12
        assert np.array_equal(back.command[:, i, 0], triangle.v[i])
        assert np.array_equal(back.command[:, i, 1], triangle.omega[i])
    for follower in ("R2", "F"):
        i = triangle.index(follower)
        e1, e2 = triangle.output_errors(follower)
        assert np.array_equal(back.errors[:, i, 0], e1) and np.array_equal(back.errors[:, i, 1], e2)
        # the recorded errors are the result's: their statistics are the summary's numbers
        block = triangle.follower_metrics(follower)
        first = next(key for key in block if key.endswith("_error"))
        assert math.isclose(np.abs(back.errors[:, i, 0]).max(), block[first]["max"], rel_tol=1e-12)
    assert np.abs(back.reference[:, 0] - triangle.x_d).max() < 1e-12
    assert np.abs(back.reference[:, 1] - triangle.y_d).max() < 1e-12
    summary = triangle.to_dict()
    assert back.summary["robots"] == json.loads(json.dumps(summary["robots"]))
    assert back.robots[triangle.index("F")]["parents"] == ["leader", "R2"]
    assert set(back.links) == {"leader->R2", "leader->F", "R2->F"}


def test_channels_use_foxglove_schemas(triangle, tmp_path):
    path = write_recording(from_result(triangle, every=10), tmp_path / "run.mcap")
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert topics["/tf"].name == "foxglove.FrameTransform"
    assert topics["/robots/leader/pose"].name == "foxglove.PoseInFrame"
    assert topics["/reference/pose"].name == "foxglove.PoseInFrame"
    assert topics["/scene"].name == "foxglove.SceneUpdate"
    assert all(s.encoding == "jsonschema" for s in topics.values())
    assert all(c.message_encoding == "json" for c in summary.channels.values())
    counts = summary.statistics.channel_message_counts
    by_topic = {c.topic: counts[i] for i, c in summary.channels.items()}
    samples = len(range(0, triangle.t.size, 10)) + (1 if (triangle.t.size - 1) % 10 else 0)
    assert by_topic["/robots/F/pose"] == samples
    assert by_topic["/tf"] == 3 * samples
    # a scene message holds a link segment per formation link, between the robots' positions
    with open(path, "rb") as stream:
        scene = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=["/scene"])]
    last = scene[-1]["entities"]
    links = next(e for e in last if e["id"] == "links")["lines"][0]["points"]
    assert len(links) == 6
    assert math.isclose(links[0]["x"], triangle.x[0][-1]) and math.isclose(links[1]["x"], triangle.x[1][-1])


def test_run_record_cli(tmp_path, capsys):
    scenario = tmp_path / "short.toml"
    scenario.write_text('name = "short"\n[simulation]\nduration = 2.0\ndt = 0.01\n[reference]\nkind = "line"\n'
                        '[[robots]]\nname = "leader"\ncontroller = "kanayama"\n')
    out = tmp_path / "short.mcap"
    assert main(["run", str(scenario), "--record", str(out), "--every", "3", "--json", "--quiet"]) == 0
    summary = json.loads(capsys.readouterr().out)
    back = read_recording(out)
    assert back.t.size == 68 and back.t[-1] == pytest.approx(2.0)
    assert np.abs(back.errors[:, 0, 0]).max() == pytest.approx(summary["robots"]["leader"]["error"]["max"],
                                                              rel=1e-9)


@pytest.mark.parametrize("content", [b"", b"not an mcap file at all", None])
def test_bad_recordings_are_one_line(tmp_path, triangle, content):
    bad = tmp_path / "bad.mcap"
    if content is None:   # a real recording cut in half
        data = write_recording(from_result(triangle, every=5), tmp_path / "good.mcap").read_bytes()
        content = data[: len(data) // 2]
    bad.write_bytes(content)
    with pytest.raises(NonholoInputError) as info:
        read_recording(bad)
    assert "\n" not in str(info.value) and str(bad) in str(info.value)
    with pytest.raises(NonholoInputError, match="no such file"):
        read_recording(tmp_path / "missing.mcap")


def test_out_directory_replays_the_run(triangle, tmp_path):
    from nonholo.view.data import from_outdir

    summary = triangle.to_dict()
    write_csv_only = tmp_path / "out"
    write_csv_only.mkdir()
    (write_csv_only / "result.json").write_text(json.dumps(summary))
    triangle.write_csv(write_csv_only / "trajectories.csv")
    back = from_outdir(write_csv_only)
    assert back.names == list(triangle.names) and back.reference is None
    assert np.abs(back.t - triangle.t).max() < 1e-9
    for i in range(len(triangle.names)):
        assert np.abs(back.pose[:, i, 0] - triangle.x[i]).max() < 1e-8 * max(1.0, np.abs(triangle.x[i]).max())
        scale = max(1.0, np.abs(triangle.omega[i]).max())
        assert np.abs(back.command[:, i, 1] - triangle.omega[i]).max() < 1e-8 * scale
    e1, e2 = triangle.output_errors("F")
    assert np.abs(back.errors[:, 2, 1] - e2).max() < 1e-8 * max(1.0, np.abs(e2).max())   # 9 digits in the CSV
    assert back.robots[2]["outputs"] == ["l1", "l2"] and back.robots[2]["parents"] == ["leader", "R2"]
    assert back.page()["links"].keys() == {"leader->R2", "leader->F", "R2->F"}
    # damaged directories: one line each
    (write_csv_only / "trajectories.csv").write_text("t_s,robot\n0,leader\n")
    with pytest.raises(NonholoInputError, match="no column x_m"):
        from_outdir(write_csv_only)
    triangle.write_csv(write_csv_only / "trajectories.csv")
    (write_csv_only / "result.json").write_text("{")
    with pytest.raises(NonholoInputError, match="not a nonholo result"):
        from_outdir(write_csv_only)


def test_too_large_a_recording_is_refused_before_writing(triangle, tmp_path, monkeypatch):
    from nonholo.view import record

    monkeypatch.setattr(record, "MAX_MESSAGES", 1000)
    with pytest.raises(ValueError, match="more than 1000"):
        write_recording(from_result(triangle), tmp_path / "big.mcap")
    assert not (tmp_path / "big.mcap").exists()
    write_recording(from_result(triangle, every=40), tmp_path / "small.mcap")   # 11 samples: 154 messages
