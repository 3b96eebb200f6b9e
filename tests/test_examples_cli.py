"""`nonholo examples` and unknown example names (issue 11 item 6)."""
import json

import pytest

from nonholo import examples
from nonholo.cli import main


def test_every_bundled_example_has_a_description():
    assert set(examples.DESCRIPTIONS) == set(examples.names())


def test_examples_lists_each_with_one_line(capsys):
    assert main(["examples"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in examples.names():
        [line] = [line for line in lines if line.startswith(name + " ")]
        assert examples.describe(name) in line
    assert max(len(line.encode()) for line in lines) <= 100


def test_examples_show_path_and_json(capsys):
    assert main(["examples", "--path", "test2-line"]) == 0
    assert capsys.readouterr().out.strip().endswith("test2-line.toml")
    assert main(["examples", "--show", "test2-line"]) == 0
    assert 'name = "test2-line"' in capsys.readouterr().out
    assert main(["examples", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)) == set(examples.names())
    assert main(["examples", "--show", "nope"]) == 2
    assert "test1-eight" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["run", "test5"], ["sweep", "test5", "--gain", "kx=1:2:2"]])
def test_unknown_names_list_the_examples(capsys, command):
    assert main(command) == 2
    err = capsys.readouterr().err
    assert "no bundled example" in err and "test1-eight" in err and "nonholo examples" in err
    assert err.count("\n") == 1


def test_paths_still_resolve_as_files(tmp_path):
    assert examples.resolve(str(tmp_path / "missing.toml")) == tmp_path / "missing.toml"
    assert examples.resolve("test2-line") == examples.path("test2-line")
    assert examples.resolve("some/dir/file") == examples.Path("some/dir/file")
