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


def test_the_program_leaves_what_is_alive_at_exit_to_the_operating_system():
    """Run as the program, ``nonholo`` freezes what is alive once the exit handlers have run
    (Python's shutdown collections would traverse it all to free memory the operating system
    takes back anyway): an exit handler registered before ``main`` runs after its own and sees
    the objects frozen; files written by the command are complete. Called from Python,
    ``main`` registers nothing."""
    import atexit
    import subprocess
    import sys

    code = ("import atexit, gc, sys\n"
            "atexit.register(lambda: print('frozen at exit:', gc.get_freeze_count() > 10_000, flush=True))\n"
            "sys.argv = ['nonholo', 'examples']\n"
            "from nonholo.cli import main\n"
            "print('exit code', main(), 'frozen before exit:', gc.get_freeze_count() > 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "exit code 0 frozen before exit: False" in out.stdout and "test1-eight" in out.stdout
    assert out.stdout.rstrip().endswith("frozen at exit: True")
    registered = []
    atexit_register, atexit.register = atexit.register, registered.append
    try:
        assert main(["examples"]) == 0
    finally:
        atexit.register = atexit_register
    assert registered == []


_CHURN = """
import resource, sys
import numpy as np
from nonholo.cli import tune_memory
tuned = tune_memory()["malloc"] if sys.argv[1] == "tuned" else None
def churn():   # a recorded run's pattern: several arrays of a few MB, filled, then all freed
    arrays = [np.empty(2**19) for _ in range(4)]   # 4 MiB each
    for a in arrays:
        a.fill(1.0)
for _ in range(3):
    churn()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    churn()
print(tuned, (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 20)
"""


def test_the_program_s_allocator_keeps_freed_arrays_for_the_next_ones():
    """Run as the program, ``nonholo`` sets glibc's malloc thresholds (``tune_memory``):
    arrays of a few MB, freed and allocated again, are served from memory already mapped
    instead of being faulted in again page by page (about 2,000 faults a round here without)."""
    import subprocess
    import sys

    import pytest

    def faults(mode):
        out = subprocess.run([sys.executable, "-c", _CHURN, mode], capture_output=True, text=True, timeout=60,
                             check=True).stdout.split()
        return out[0], float(out[1])

    tuned, with_tuning = faults("tuned")
    if tuned != "True":
        pytest.skip("no glibc mallopt here (the tuning is for glibc's malloc only)")
    _, without = faults("default")
    assert with_tuning < 50 < 1_000 < without


def test_huge_page_advice_is_turned_off_where_the_kernel_would_compact_for_it():
    """Where transparent huge pages are compacted on demand (THP defrag "madvise" or
    "always"), the program asks numpy not to advise them (``tune_memory``); elsewhere it
    leaves numpy's default. Checked in a fresh process, whose numpy state it then reads."""
    import subprocess
    import sys

    code = ("from nonholo.cli import tune_memory\ntaken = tune_memory()\ntry:\n"
            "    from numpy._core.multiarray import _set_madvise_hugepage as switch\nexcept ImportError:\n"
            "    from numpy.core.multiarray import _set_madvise_hugepage as switch\n"
            "print(taken['hugepages_off'], switch(True))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         check=True).stdout.split()
    try:
        with open("/sys/kernel/mm/transparent_hugepage/defrag") as handle:
            defrag = handle.read()
        compacting = any(f"[{mode}]" in defrag for mode in ("madvise", "defer+madvise", "always"))
    except OSError:
        compacting = False
    assert out[0] == str(compacting)
    if compacting:
        assert out[1] == "False"   # the advice was off when it was switched back on
