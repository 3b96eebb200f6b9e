"""nonholo.view: see the fleet — MCAP recordings, replay and a live page in the browser.

Layers, each importing only those above it::

    data      a finished run on one grid (from a result, an --out directory or a recording)
    record    MCAP recordings: write a run, read one back
    feed      the bounded, latest-wins feed of live snapshots (and a fleet's snapshot)
    server    the page's HTTP + WebSocket server (aiohttp), loopback and token only
    foxglove_live  the feed to a Foxglove WebSocket server (optional: ``nonholo[foxglove]``)

``record`` needs ``mcap`` and ``server`` needs ``aiohttp``: ``pip install 'nonholo[view]'``.
"""
from __future__ import annotations

import importlib

from nonholo.errors import NonholoInputError

EXTRA = "view"


def require(module: str, extra: str = EXTRA) -> None:
    """Import check for the optional dependencies: one line naming the extra to install."""
    try:
        importlib.import_module(module)
    except ImportError:
        raise NonholoInputError(f"this needs the Python module {module!r}: "
                                f"python3 -m pip install 'nonholo[{extra}]'") from None
