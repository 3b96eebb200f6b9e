"""Where numba keeps nonholo's compiled code: a per-user cache directory, never the
installed package.

numba's default (``cache=True``) writes ``.nbi``/``.nbc`` files into ``__pycache__`` beside
the source, i.e. into ``site-packages/nonholo/`` after ``pip install .``. Those files
survive ``pip uninstall``; the folder they leave behind is then an implicit namespace
package that hides a later editable install (``ImportError: cannot import name
'__version__' from 'nonholo' (unknown location)``). So nonholo's compiled code goes to

* ``$NUMBA_CACHE_DIR`` if the user set it (numba's own rule, applied to everything), else
* ``$XDG_CACHE_HOME/nonholo/numba``, or ``~/.cache/nonholo/numba`` (``%LOCALAPPDATA%`` on
  Windows, ``~/Library/Caches`` on macOS),
* else, if that cannot be written, a per-user folder in the temporary directory;

one sub-folder per source folder of the package, named after its path *inside* the package
(``sim_<hash of "nonholo/sim">``), not after its absolute path: the installed copy and an
editable checkout of the same source share their compiled code (the README's two commands:
the tests reuse what the first run compiled).

**Stamp.** numba stamps each function's cache index with a hash of the function's own file
only, so a caller kept the old code of a compiled helper edited in another module (measured:
``watchdog_update`` edited, the link step that calls it still ran the old one, even after
its own file was touched). nonholo's functions are stamped with a digest of the whole
package's source instead (``package_digest``), and that digest is part of every cache file's
name: an edit anywhere compiles every function again when it is next used, copies of one
source share their files, and different sources never read or write each other's (two
checkouts side by side each keep theirs). Files of other sources not modified for two weeks
are removed (``prune_once``), so edits and upgrades do not pile up.

**Locks.** numba saves a new overload by reading the function's index, taking the first free
data file number, writing the index, then the data; two processes saving overloads of one
function at once (two test workers, a study's helpers) could pair one's key with the other's
code. nonholo's cache files are saved under an exclusive ``flock`` on ``<index>.lock`` and
loaded under a shared one (``index_lock``, ``_locked_cache_files``).

How: numba asks a list of *cache locators*, in order, where a function's cache lives; the
first that accepts the function wins. ``install()`` (run by ``import nonholo``, before any
nonholo module compiles anything) puts ``PackageCacheLocator`` first, before numba's
``$NUMBA_CACHE_DIR`` locator (it uses that folder too when it is set). It accepts only
functions whose source file lies inside this package, so the user's own ``cache=True``
functions keep numba's defaults, and it works
whether or not numba was imported first: the locator is chosen when a function is
decorated, which happens when nonholo's modules are imported, always after
``nonholo/__init__`` has run. (Setting ``numba.config.CACHE_DIR`` instead would also move
every other library's caches; setting ``os.environ`` would leak into child processes.) If
``$NUMBA_CACHE_LOCATOR_CLASSES`` is set, numba uses exactly that list and we do not
interfere.

>>> from nonholo.numba_cache import cache_dir
>>> "nonholo" in str(cache_dir()) or bool(__import__("os").environ.get("NUMBA_CACHE_DIR"))
True
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import sys
import tempfile
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def user_cache_root() -> Path:
    """The platform's per-user cache folder (``$XDG_CACHE_HOME`` or ``~/.cache`` on Linux)."""
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"


def cache_dir() -> Path:
    """Where nonholo's compiled code is cached (see the module docstring)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return Path(user)
    return user_cache_root() / "nonholo" / "numba"


def _fallback_dir() -> Path:
    import getpass

    try:
        user = getpass.getuser()
    except Exception:  # no user name in the environment or the password database
        user = str(getattr(os, "getuid", lambda: "user")())
    return Path(tempfile.gettempdir()) / f"nonholo-numba-{user}"


@functools.lru_cache(maxsize=None)
def package_sources() -> tuple[Path, ...]:
    """Every ``.py`` file of the package, in path order (listed once per process)."""
    return tuple(sorted(PACKAGE_DIR.rglob("*.py")))


@functools.lru_cache(maxsize=None)
def package_digest() -> bytes:
    """SHA-256 over every ``.py`` file of the package (its path inside the package and its
    bytes, in path order): the stamp of every nonholo function's cache index. Once per
    process (1.2 MB of source, a few ms)."""
    digest = hashlib.sha256()
    for path in package_sources():
        digest.update(path.relative_to(PACKAGE_DIR).as_posix().encode("utf-8") + b"\0")
        try:
            digest.update(path.read_bytes())
        except OSError as exc:   # an unreadable file still changes the stamp, and never stops an import
            digest.update(f"unreadable: {exc.errno}".encode("utf-8"))
        digest.update(b"\0")
    return digest.digest()


def digest_tag() -> str:
    """The short form of ``package_digest`` in cache file names."""
    return package_digest().hex()[:12]


def subfolder(source_dir: Path) -> str:
    """The cache sub-folder of a source folder of the package, named after its place in the
    package (``sim_<sha1 of "nonholo/sim">``), not its absolute path."""
    inside = source_dir.relative_to(PACKAGE_DIR.parent).as_posix()
    return f"{inside.rsplit('/', 1)[-1]}_{hashlib.sha1(inside.encode('utf-8')).hexdigest()}"


PRUNE_AFTER_S = 14 * 86400   # files of other sources untouched this long go


@functools.lru_cache(maxsize=None)
def prune_once(root: Path) -> int:
    """Remove, once per process and cache root, the compiled files of *other* sources of
    the package (another digest in the name) not modified for ``PRUNE_AFTER_S``: each edit
    or upgrade leaves a set behind. Only nonholo's own sub-folders are looked at; errors
    (a file gone, no permission) are ignored. Returns how many files went."""
    import time

    current, removed = f"-{digest_tag()}.", 0
    cutoff = time.time() - PRUNE_AFTER_S
    folders = {subfolder(path.parent) for path in package_sources()}
    for name in folders:
        try:
            entries = list(os.scandir(root / name))
        except OSError:
            continue
        for entry in entries:
            if not entry.name.endswith((".nbi", ".nbc")) or current in entry.name:
                continue
            try:
                if entry.stat().st_mtime < cutoff:
                    os.unlink(entry.path)
                    removed += 1
            except OSError:
                pass
    return removed


def _make_locator():
    from numba.core import caching

    class PackageCacheLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        """numba cache locator: nonholo's functions cache under ``cache_dir()``."""

        root: Path | None = None  # chosen on first use: cache_dir(), else the fallback

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = str(self.root / self.get_suitable_cache_subpath(py_file))

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            return package_digest()

        def get_disambiguator(self):
            # the source's digest in the file names: copies of one source share them, and two
            # sources never write the same index or data file (numba writes an index, then its
            # data: two processes of different sources interleaving there could pair one's
            # index with the other's code)
            return f"{self._lineno}-{digest_tag()}"

        @classmethod
        def get_suitable_cache_subpath(cls, py_file):
            return subfolder(Path(py_file).resolve().parent)

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                if not Path(py_file).resolve().is_relative_to(PACKAGE_DIR):
                    return None
            except (OSError, ValueError):
                return None
            roots = [cls.root] if cls.root is not None else [cache_dir(), _fallback_dir()]
            for root in roots:
                cls.root = root
                locator = super().from_function(py_func, py_file)  # None if the folder cannot be written
                if locator is not None:
                    prune_once(root)
                    return locator
            cls.root = None
            return None

    return PackageCacheLocator


@contextlib.contextmanager
def index_lock(lock_path: str | None, shared: bool):
    """An ``flock`` on ``lock_path`` (``<index>.lock`` beside a cache index) while a process
    reads (shared) or writes (exclusive) that function's cache: see ``_locked_cache_files``.
    No lock for ``None`` (not nonholo's cache), without ``fcntl`` (Windows) or a writable
    folder."""
    try:
        import fcntl

        handle = open(lock_path, "a+b") if lock_path is not None else None
    except (ImportError, OSError):
        handle = None
    if handle is None:
        yield
        return
    with handle:   # (closing it releases the lock)
        fcntl.flock(handle, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        yield


def _locked_cache_files(caching, locator) -> None:
    """numba saves a new compiled overload by loading the function's index, taking the first
    free data file number, writing the index, then the data; every overload of a function
    (every law's batch kernel, every law's C entry) shares one index. Two processes saving
    two overloads at once (the test suite's two workers, a study's helpers) can take the same
    number, and the index can end up pairing one's key with the other's code: another law's
    kernel, run silently, from then on. So nonholo's cache files (those under
    ``locator.root``) are saved holding an exclusive lock on their index and loaded holding a
    shared one (``index_lock``); other functions' caches are left as numba makes them."""
    base = getattr(caching, "IndexDataCacheFile", None)
    if base is None or getattr(base, "nonholo_locked", False):   # (a numba without it: as it is)
        return

    class LockedIndexDataCacheFile(base):
        nonholo_locked = True

        def __init__(self, cache_path, *args, **kwargs):
            super().__init__(cache_path, *args, **kwargs)
            ours = locator.root is not None and Path(cache_path).parent == locator.root
            self._lock_path = self._index_path + ".lock" if ours else None

        def save(self, key, data):
            with index_lock(self._lock_path, shared=False):
                return super().save(key, data)

        def load(self, key):
            with index_lock(self._lock_path, shared=True):
                return super().load(key)

    caching.IndexDataCacheFile = LockedIndexDataCacheFile


def install() -> None:
    """Make numba cache nonholo's compiled code under ``cache_dir()``, its cache files saved
    and loaded under a lock (idempotent)."""
    try:
        from numba.core import caching
        impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # renamed in numba 0.61
        locators = impl._locator_classes
    except (ImportError, AttributeError):  # a numba without this mechanism: keep its defaults
        return
    if any(getattr(c, "__name__", "") == "PackageCacheLocator" for c in locators):
        return
    locator = _make_locator()
    locators.insert(0, locator)
    _locked_cache_files(caching, locator)
