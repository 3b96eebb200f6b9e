"""The ``nonholo`` program tunes Python's garbage collector for long commands; called from
Python, the CLI leaves the caller's collector as it found it."""
import gc

from nonholo.cli import PROGRAM_GC_THRESHOLD, collector_for_long_work, main


def test_a_long_command_freezes_what_is_alive_and_lets_it_go_after():
    assert gc.get_freeze_count() == 0
    with collector_for_long_work():
        assert gc.get_freeze_count() > 1000   # the imported modules' objects, at least
        garbage = [[]]
        garbage[0].append(garbage)   # a cycle made inside the block is still collected
        del garbage
        assert gc.collect() > 0
    assert gc.get_freeze_count() == 0


def test_main_called_from_python_keeps_the_caller_s_thresholds(capsys):
    before = gc.get_threshold()
    assert before != PROGRAM_GC_THRESHOLD
    assert main(["examples"]) == 0
    assert "test1-eight" in capsys.readouterr().out
    assert gc.get_threshold() == before
