"""The link model (spec fleet.md §3–4): per link, a delay (fixed plus seeded jitter) and a
loss probability, drawn from a generator of its own in message order.

One pure draw serves both sides of the equality contract: the fleet's transport layer
applies it to the frames it sends, the centralized sampled-data simulator to the states
it passes from parent to child, so both see the same usable-message sequence.

Message j of a link is the parent's state of control instant j (t_j = j T). Its draw is
``(delay_j, lost_j)``; it becomes usable at the first instant t_k ≥ t_j + delay_j, that is
``k = j + ceil(delay_j / T − 1e-9)`` (the tolerance keeps a delay of exactly 2T at two
instants despite rounding). Without ``reorder`` a message is never usable before the one
sent before it (the instant is raised to the previous usable one, as a FIFO link does).
A lost message is never usable.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

LOST = -1               # usable instant of a lost message
TICK_TOLERANCE = 1e-9   # in control periods


@dataclass(frozen=True)
class LinkModel:
    """``delay`` s fixed, plus jitter uniform in [0, ``jitter``] s; ``loss`` probability in
    [0, 1); ``reorder`` lets a later message overtake an earlier one."""

    delay: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    reorder: bool = False

    def __post_init__(self) -> None:
        for name in ("delay", "jitter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 3600:
                raise ValueError(f"{name} must be a number of seconds in [0, 3600], got {value!r}")
        if isinstance(self.loss, bool) or not isinstance(self.loss, (int, float)) or not 0 <= self.loss < 1:
            raise ValueError(f"loss must be a probability in [0, 1), got {self.loss!r}")
        if not isinstance(self.reorder, bool):
            raise ValueError(f"reorder must be true or false, got {self.reorder!r}")

    @property
    def ideal(self) -> bool:
        return self.delay == 0 and self.jitter == 0 and self.loss == 0


IDEAL = LinkModel()


def link_generator(seed: int, parent: str, child: str) -> np.random.Generator:
    """The generator of link ``parent → child`` under ``seed`` (independent of every other
    link and of the order in which links are created)."""
    digest = hashlib.sha256(f"{parent}\x00{child}".encode("utf-8")).digest()
    words = [int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4)]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed) & (2**64 - 1), *words])))


def link_draws(model: LinkModel, seed: int, parent: str, child: str, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(delays, lost)`` of messages 0..count−1 of link ``parent → child``: delays in
    seconds (float array), lost flags (bool array). Prefix-stable: message j's draw does
    not depend on ``count``. Each message takes two uniform numbers, (jitter, loss)."""
    uniforms = link_generator(seed, parent, child).random((int(count), 2))
    delays = model.delay + model.jitter * uniforms[:, 0]
    lost = uniforms[:, 1] < model.loss
    return delays, lost


def usable_instants(model: LinkModel, seed: int, parent: str, child: str, count: int,
                    period: float) -> np.ndarray:
    """Per message j (0..count−1), the control instant from which it is usable, or ``LOST``."""
    delays, lost = link_draws(model, seed, parent, child, count)
    ticks = np.ceil(delays / period - TICK_TOLERANCE).astype(np.int64)
    usable = np.arange(count, dtype=np.int64) + np.maximum(ticks, 0)
    if not model.reorder:
        kept = ~lost
        usable[kept] = np.maximum.accumulate(usable[kept]) if kept.any() else usable[kept]
    usable[lost] = LOST
    return usable


def newest_usable(usable: np.ndarray, instants: int) -> np.ndarray:
    """Per control instant k (0..instants−1), the index j of the newest message usable at
    k (the largest j with ``0 <= usable[j] <= k``), or −1 when none is."""
    newest = np.full(instants, -1, dtype=np.int64)
    for j, k in enumerate(usable):
        if 0 <= k < instants:
            newest[k] = max(newest[k], j)
    return np.maximum.accumulate(newest) if instants else newest


def link_schedule(model: LinkModel, seed: int, parent: str, child: str, instants: int,
                  period: float) -> np.ndarray:
    """The usable-message sequence of a link over ``instants`` control instants: per k,
    the newest usable message index (−1: none yet). Both the fleet and the centralized
    simulator call this."""
    return newest_usable(usable_instants(model, seed, parent, child, instants, period), instants)


def age_instants(schedule: np.ndarray) -> np.ndarray:
    """Per instant k, the age k − j of the message used (in control periods; −1: none)."""
    k = np.arange(len(schedule))
    return np.where(schedule >= 0, k - schedule, -1)

