"""Compiled code is cached per user, never inside the installed package (issue: a leftover
``site-packages/nonholo/__pycache__`` hid a later editable install)."""
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def warm_cache(tmp_path) -> dict:
    """An environment whose numba cache folder starts as a copy of this session's: the
    package's own functions load from it, so a run compiles only the test's own law (what
    these tests are about) instead of every kernel again."""
    from nonholo.numba_cache import cache_dir

    target = tmp_path / "numba"
    if cache_dir().is_dir():
        shutil.copytree(cache_dir(), target)
    return {**os.environ, "NUMBA_CACHE_DIR": str(target)}

PROBE = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import numba  # imported before nonholo on purpose
    from numba import njit
    import nonholo
    from nonholo import numerics
    sys.path.insert(0, sys.argv[2])
    import user_module
    print(numerics._sin_cos_arrays._cache._cache_path)
    print(user_module.double._cache._cache_path)
""")


def _probe(tmp_path, **env):
    user = tmp_path / "user"
    user.mkdir(exist_ok=True)
    (user / "user_module.py").write_text("from numba import njit\n\n@njit(cache=True)\ndef double(x):\n    return 2 * x\n")
    environment = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    environment.update(env)
    out = subprocess.run([sys.executable, "-c", PROBE, str(ROOT), str(user)], env=environment, check=True,
                         capture_output=True, text=True).stdout.split()
    return Path(out[0]), Path(out[1])


def test_nonholo_caches_under_the_user_cache_folder(tmp_path):
    ours, theirs = _probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "cache"))
    assert ours.parent == tmp_path / "cache" / "nonholo" / "numba"
    assert ours.name.startswith("nonholo_")
    assert not ours.is_relative_to(ROOT)
    # other libraries' functions keep numba's own default
    assert theirs == tmp_path / "user" / "__pycache__"


def test_numba_cache_dir_is_respected(tmp_path):
    ours, theirs = _probe(tmp_path, XDG_CACHE_HOME=str(tmp_path / "cache"), NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    assert ours.parent == tmp_path / "numba" and theirs.parent == tmp_path / "numba"


def test_unwritable_cache_folder_falls_back_outside_the_package(tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    ours, _ = _probe(tmp_path, XDG_CACHE_HOME=str(blocked))
    assert not ours.is_relative_to(ROOT) and "nonholo-numba-" in str(ours)


LAW_MODULE = textwrap.dedent("""
    from numba import njit
    from nonholo.control.declare import POSITIVE, Gain, control_law

    @njit(error_model="numpy")
    def gone_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
        return gains.k * (1.0 + 0.0 * x), 0.2, 0.0, 0.0

    control_law("gone-law", title="a law whose module is deleted later", source="tests",
                gains={"k": Gain(1.0, POSITIVE)}, stiffness=lambda g, v_d, omega_d: g["k"])(gone_law)
""")

RUN = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    sys.path.insert(0, sys.argv[2])
    import nonholo
    from nonholo import references
    from nonholo.studies.solver_steps import solver_step_statistics
    if sys.argv[3] == "gone-law":
        import gone_laws
    scenario = nonholo.Scenario(references.line(), [nonholo.Robot("r", nonholo.controller(sys.argv[3]), (0.1, 0.2, 0.0))],
                                duration=1.0, dt=0.01)
    nonholo.simulate(scenario)
    solver_step_statistics(scenario)
    print("ok")
""")


def test_a_removed_law_does_not_break_the_cache_of_the_others(tmp_path):
    # A law registered from a user module compiles, and caches, code of its own; once that
    # module is gone, every other law's cached functions must still load (numba keeps one
    # cache index per function for every law: no entry in it may name the law's types).
    user = tmp_path / "user"
    user.mkdir()
    (user / "gone_laws.py").write_text(LAW_MODULE)
    environment = warm_cache(tmp_path)
    for law in ("gone-law", "kanayama"):
        if law == "kanayama":
            (user / "gone_laws.py").unlink()
        done = subprocess.run([sys.executable, "-c", RUN, str(ROOT), str(user), law], env=environment,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0 and done.stdout.split()[-1] == "ok", done.stderr[-2000:]


EDITED = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    sys.path.insert(0, sys.argv[2])
    import nonholo
    from nonholo import references
    import edited_laws
    robot = nonholo.Robot("r", nonholo.controller("edited-law"), (0.1, 0.2, 0.0))
    run = nonholo.simulate(nonholo.Scenario(references.line(), [robot], duration=1.0, dt=0.01), record=False)
    print(run.to_dict()["robots"]["r"]["control"]["peak_v"])
""")


def test_an_edited_law_is_compiled_again_not_served_from_the_cache(tmp_path):
    # A single run calls the law through its C entry, cached on disk with the law's code in
    # its key: editing the law's body, or the order of its declared gains (the entry reads
    # them by position), must change the numbers, not load the old entry.
    user = tmp_path / "user"
    user.mkdir()
    environment = warm_cache(tmp_path)
    source = LAW_MODULE.replace("gone", "edited").replace("gains.k * (1.0 + 0.0 * x)", "FACTOR * gains.k")
    source = source.replace('gains={"k": Gain(1.0, POSITIVE)}', 'gains={GAINS}')
    k, j = '"k": Gain(1.0, POSITIVE)', '"j": Gain(3.0, POSITIVE)'
    for factor, gains in ((1.0, f"{k}, {j}"), (2.0, f"{k}, {j}"), (2.0, f"{j}, {k}")):
        (user / "edited_laws.py").write_text(source.replace("FACTOR", str(factor)).replace("GAINS", gains))
        done = subprocess.run([sys.executable, "-c", EDITED, str(ROOT), str(user)], env=environment,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        assert float(done.stdout.split()[-1]) == factor


STAMP_PROBE = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import numpy as np
    from nonholo.sim.linkstep import parent_pose
    inbox = np.zeros((5, 2, 1, 1))
    inbox[:, 0, 0, 0] = (1.0, 0.0, 0.0, 1.0, 0.0)   # x, y, theta, v, omega
    print(parent_pose(inbox, 0, 0, 0, 2.0, 1.0)[0], sum(parent_pose.stats.cache_hits.values()))
""")


def test_copies_of_one_source_share_compiled_code_and_an_edited_helper_is_not_served_stale(tmp_path):
    """The cache folder is named after a source folder's place inside the package, so two
    copies of the same source (the installed one and an editable checkout) share compiled
    code; every index is stamped with the whole package's source, so editing a compiled
    helper (``unicycle_arc``, models/unicycle.py) recompiles its caller in another module
    (``parent_pose``, sim/linkstep.py), which numba's per-file stamp served stale."""
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    copies = []
    for name in ("installed", "checkout"):
        shutil.copytree(ROOT / "nonholo", tmp_path / name / "nonholo", ignore=shutil.ignore_patterns("__pycache__"))
        copies.append(tmp_path / name)

    def probe(copy):
        done = subprocess.run([sys.executable, "-c", STAMP_PROBE, str(copy)], env=environment, capture_output=True,
                              text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        x, hits = done.stdout.split()[-2:]
        return float(x), int(hits)

    assert probe(copies[0]) == (3.0, 0)    # compiled: the pose advanced 2 s at 1 m/s
    assert probe(copies[1]) == (3.0, 1)    # the other copy loads it
    helper = copies[1] / "nonholo" / "models" / "unicycle.py"
    source = helper.read_text()
    edited = source.replace("return x + chord * math.cos(mid)", "return 100.0 + x + chord * math.cos(mid)")
    assert edited != source
    helper.write_text(edited)
    assert probe(copies[1]) == (103.0, 0)   # compiled again with the edited helper
    assert probe(copies[0]) == (3.0, 1)     # and the other source's code is still there, its own


def test_compiled_files_of_other_sources_go_after_two_weeks(tmp_path):
    from nonholo.numba_cache import PRUNE_AFTER_S, digest_tag, prune_once, subfolder

    folder = tmp_path / subfolder(ROOT / "nonholo" / "sim")
    folder.mkdir()
    old = time.time() - PRUNE_AFTER_S - 60
    files = {name: folder / name for name in (
        "kernel.f-10-0123456789ab.py311.nbi", "kernel.f-10-0123456789ab.py311.1.nbc",   # another source, old
        "kernel.f-10-fedcba987654.py311.nbi",                                          # another source, recent
        f"kernel.f-10-{digest_tag()}.py311.nbi",                                        # this source, old
        "notes.txt")}                                                                   # not a cache file
    for path in files.values():
        path.write_text("x")
    for name in ("kernel.f-10-0123456789ab.py311.nbi", "kernel.f-10-0123456789ab.py311.1.nbc",
                 f"kernel.f-10-{digest_tag()}.py311.nbi", "notes.txt"):
        os.utime(files[name], (old, old))
    assert prune_once.__wrapped__(tmp_path) == 2
    assert sorted(p.name for p in folder.iterdir()) == sorted(list(files)[2:])


@pytest.mark.skipif(sys.platform == "win32", reason="flock is POSIX")
def test_nonholo_s_cache_files_are_saved_under_an_exclusive_lock_and_loaded_under_a_shared_one(tmp_path, monkeypatch):
    # numba's save is load-index, take a free data number, write index, write data: two
    # processes saving two overloads of one function at once could pair one's key with the
    # other's code. nonholo's index files are locked around both (numba_cache.index_lock).
    import fcntl
    import threading

    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    locator = next(c for c in impl._locator_classes if c.__name__ == "PackageCacheLocator")
    monkeypatch.setattr(locator, "root", tmp_path / "root")
    ours, theirs = tmp_path / "root" / "sim_x", tmp_path / "elsewhere"
    ours.mkdir(parents=True)
    theirs.mkdir()

    def blocked(call, *args):
        """Whether ``call(*args)`` is still waiting after 0.3 s, and its thread."""
        worker = threading.Thread(target=call, args=args, daemon=True)
        worker.start()
        worker.join(0.3)
        return worker.is_alive(), worker

    files, other = (caching.IndexDataCacheFile(str(folder), "probe", "stamp") for folder in (ours, theirs))
    with open(ours / "probe.nbi.lock", "a+b") as held, open(theirs / "probe.nbi.lock", "a+b") as held_there:
        fcntl.flock(held, fcntl.LOCK_EX)
        fcntl.flock(held_there, fcntl.LOCK_EX)
        waiting, saver = blocked(files.save, "key", "compiled code")
        assert waiting and not (ours / "probe.nbi").exists()      # it waits for the lock
        assert not blocked(other.save, "key", "theirs")[0]
        assert other.load("key") == "theirs"                       # not ours: never locked
        fcntl.flock(held, fcntl.LOCK_UN)
        saver.join(10)
        assert not saver.is_alive() and files.load("key") == "compiled code"
        fcntl.flock(held, fcntl.LOCK_SH)                           # readers share it
        assert files.load("key") == "compiled code"
        fcntl.flock(held, fcntl.LOCK_EX)                           # a writer holds it: loads wait
        waiting, loader = blocked(files.load, "key")
        assert waiting
        fcntl.flock(held, fcntl.LOCK_UN)
        loader.join(10)
        assert not loader.is_alive()
