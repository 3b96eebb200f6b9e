"""Chunks of a batch, run here or on a Dask cluster: the one place where sweeps, Monte-Carlo
sets and tuning populations are split and sent.

A study is a list of ``count`` independent items (grid points, samples, population members)
with an estimated ``work`` per item in robot-steps (robots × output steps × RK4 sub-steps).
``chunk_bounds`` cuts it into contiguous chunks of at least ``MIN_CHUNK_SECONDS`` of
work at the nominal rate ``NOMINAL_ROBOT_STEPS_PER_S`` — a deterministic function of the
study alone, never of the machine or the cluster — and ``run_chunks`` calls a module-level
function on every chunk, in this process (the default: one process, one chunk after the
other) or on a Dask cluster (``dask="local"`` for a local cluster of worker processes, or a
scheduler address such as ``tcp://10.0.0.5:8786``). Because the chunks are the same either
way, so are the results, bit for bit: members simulated together are planned together, and
each chunk is one batch on both paths.

Chunk functions receive picklable payloads: scenarios travel as their TOML text and are
parsed once per worker process (``scenario_of``), because a scenario object holds compiled
functions.
"""
from __future__ import annotations

import contextlib
import logging
import math
import sys
from collections.abc import Callable, Iterator, Sequence
from functools import lru_cache

from nonholo.errors import NonholoInputError

# The kernel's batch throughput on one core is 4–10·10⁷ robot-steps/s. Chunks aim at
# CHUNK_SECONDS of work at the nominal rate: far above the ≥ 100 ms that makes a chunk worth
# sending, and large enough that the per-batch set-up (reference tables, sub-step plans)
# stays a few per cent; a chunk is never smaller than MIN_CHUNK_SECONDS unless the whole
# study is, and never more than MAX_CHUNK_ITEMS items (memory; progress granularity).
NOMINAL_ROBOT_STEPS_PER_S = 5e7
CHUNK_SECONDS = 1.0
MIN_CHUNK_SECONDS = 0.1
MAX_CHUNK_ITEMS = 20_000
LOCAL = "local"
INSTALL_HINT = "pip install 'nonholo[dask]'"


def chunk_bounds(count: int, work_per_item: float, seconds: float | None = None) -> list[tuple[int, int]]:
    """Contiguous ``(start, stop)`` item ranges covering ``range(count)``, as equal as
    possible, each of about ``seconds`` (default ``CHUNK_SECONDS``) of nominal work (at least ``MIN_CHUNK_SECONDS`` unless
    the whole study is less; at most ``MAX_CHUNK_ITEMS`` items).

    >>> chunk_bounds(100, 1e6)           # 1e6 robot-steps per item: 50 items make 1 s
    [(0, 50), (50, 100)]
    >>> chunk_bounds(3, 1e9)             # every item alone is worth sending
    [(0, 1), (1, 2), (2, 3)]
    """
    if count <= 0:
        return []
    seconds = CHUNK_SECONDS if seconds is None else seconds
    per_item = max(work_per_item, 1.0) / NOMINAL_ROBOT_STEPS_PER_S
    size = min(max(1, math.ceil(max(seconds, MIN_CHUNK_SECONDS) / per_item)), MAX_CHUNK_ITEMS)
    chunks = math.ceil(count / size)
    edges = [round(i * count / chunks) for i in range(chunks + 1)]
    return list(zip(edges[:-1], edges[1:]))


@lru_cache(maxsize=8)
def scenario_of(text: str, source: str = "<scenario>"):
    """The scenario of a TOML text, parsed once per process (workers reuse it across chunks)."""
    from nonholo.sim.files import parse_scenario

    name = source.rsplit("/", 1)[-1].removesuffix(".toml") or "scenario"
    return parse_scenario(text, source, name)


def check_address(address: str | None) -> str | None:
    """``None``, ``"local"`` or a scheduler address (``tcp://host:port``, ``host:port``)."""
    if address is None or address == LOCAL:
        return address
    if not address or any(c.isspace() for c in address) or ":" not in address:
        raise NonholoInputError(f"--dask must be 'local' or a scheduler address such as tcp://10.0.0.5:8786, "
                                f"got {address!r}")
    return address


def require_dask() -> None:
    """``NonholoInputError`` naming the extra to install unless Dask's ``distributed`` imports."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise NonholoInputError(f"Dask is not installed: {INSTALL_HINT}") from None


@contextlib.contextmanager
def dask_client(address: str | None, workers: int = 2) -> Iterator:
    """A ``distributed.Client`` for ``address`` ("local": a ``LocalCluster`` of ``workers``
    single-threaded processes on 127.0.0.1, dashboard off, closed on exit), or ``None``
    for the in-process path."""
    if address is None:
        yield None
        return
    require_dask()
    from distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        if address == LOCAL:
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       host="127.0.0.1", dashboard_address=None,
                                                       silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(check_address(address), timeout="20s"))
            except (OSError, TimeoutError) as exc:
                raise NonholoInputError(f"--dask: cannot reach the scheduler at {address}: {exc}"[:300]) from None
        yield client


def run_chunks(function: Callable, payloads: Sequence, client=None, progress: Callable[[int], None] | None = None,
               ) -> Iterator[tuple[int, object]]:
    """``(index, function(payload))`` for every payload, in the order the chunks finish
    (in order here; on a cluster as workers finish). ``progress(k)`` is called after each
    chunk with its index. ``client``: a ``distributed.Client`` or ``None`` (this process)."""
    if client is None:
        for index, payload in enumerate(payloads):
            result = function(payload)
            if progress is not None:
                progress(index)
            yield index, result
        return
    from distributed import as_completed

    futures = client.map(function, list(payloads), pure=False)
    where = {future.key: index for index, future in enumerate(futures)}
    try:
        for future in as_completed(futures):
            index = where[future.key]
            result = future.result()
            future.release()
            if progress is not None:
                progress(index)
            yield index, result
    finally:
        client.cancel(futures)


def progress_bar(total: int, unit: str, description: str, enabled: bool | None):
    """A tqdm bar on stderr (``enabled`` None: only on a terminal)."""
    from tqdm import tqdm

    if enabled is None:
        enabled = sys.stderr.isatty()
    return tqdm(total=total, unit=unit, desc=description, file=sys.stderr, disable=not enabled, leave=False)
