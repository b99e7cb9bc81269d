"""The live tracker's updates on their way out: stamped with the ``sent_ns`` of the packets they
came from, held until a batch is due, then published as centreline messages (at most
``batch_updates`` each), numbered, with the time of publication."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.windows import WindowSchedule
from flagtrack.daemon.schema import CentrelineMessage, EventPacket
from flagtrack.daemon.transport import Publisher


class CentrelineOutbox:
    """Updates waiting for publication.

    Args:
        source: the ``source`` of every message.
        units: the updates' length unit.
        batch_updates: updates per message at most.
        max_delay_s: a smaller batch is due this long after its first update came.
    """

    def __init__(self, source: str, units: str, batch_updates: int, max_delay_s: float) -> None:
        self.source, self.units = source, units
        self.batch_updates, self.max_delay_s = batch_updates, max_delay_s
        self._batches: list[CentrelineBatch] = []
        self._source_ns: list[np.ndarray] = []
        self._n = 0
        self._since = 0.0
        self.seq = 0  # of the next message

    def __len__(self) -> int:
        return self._n

    def add(self, batch: CentrelineBatch, source_ns: np.ndarray) -> bool:
        """Hold ``batch`` (with each update's ``sent_ns``); True when a full message's worth waits."""
        if len(batch) == 0:
            return False
        if not self._batches:
            self._since = time.monotonic()
        self._batches.append(batch)
        self._source_ns.append(source_ns)
        self._n += len(batch)
        return self._n >= self.batch_updates

    def due(self) -> bool:
        """Whether the updates held have waited ``max_delay_s``."""
        return bool(self._batches) and time.monotonic() - self._since >= self.max_delay_s

    def publish(self, pub: Publisher, stream: int, final: bool, empty: Callable[[], CentrelineBatch]) -> None:
        """Publish every update held (``final``: the last message ends ``stream``; with nothing
        held, a message of no update from ``empty()`` says so)."""
        if not self._batches and not final:
            return
        if len(self._batches) == 1:  # the usual case live: one packet's updates, published at once
            batch, source_ns = self._batches[0], self._source_ns[0]
        elif self._batches:
            batch = CentrelineBatch.concatenate(self._batches)
            source_ns = np.concatenate(self._source_ns)
        else:
            batch, source_ns = empty(), np.zeros(0, dtype=np.int64)
        self._batches, self._source_ns, self._n = [], [], 0
        starts = list(range(0, len(batch), self.batch_updates)) or [0]
        for start in starts:
            part = slice(start, start + self.batch_updates)
            lines = batch if len(starts) == 1 else batch.select(part)
            message = CentrelineMessage.from_batch(
                lines,
                source=self.source,
                seq=self.seq,
                units=self.units,
                source_ns=source_ns if len(starts) == 1 else source_ns[part],
                final=final and start == starts[-1],
                published_ns=time.time_ns(),
                stream=stream,
            )
            pub.put(message)
            self.seq += 1


def newest_packet_ns(window_ends_us: np.ndarray, horizons_us: np.ndarray, sent_ns: np.ndarray) -> np.ndarray:
    """(n,) the ``sent_ns`` of the packet holding the last µs of each window (exclusive ends
    ``window_ends_us``), among packets tracked together (horizons ``t_last_us``, in stream order).

    The latency of an update counts from the arrival of the newest events it used, even when later
    packets were tracked in the same call; a window beyond every horizon (the end of a stream) is
    given the last packet.
    """
    newest = np.searchsorted(np.maximum.accumulate(horizons_us), np.asarray(window_ends_us) - 1, side="left")
    return np.asarray(sent_ns, dtype=np.int64)[np.minimum(newest, len(sent_ns) - 1)]


def updates_source_ns(batch: CentrelineBatch, run: list[EventPacket], schedule: WindowSchedule) -> np.ndarray:
    """(n_t,) ``sent_ns`` of the packet of ``run`` that brought each update's newest events."""
    if len(run) == 1 or len(batch) == 0:
        return np.full(len(batch), run[-1].sent_ns, dtype=np.int64)
    return newest_packet_ns(
        schedule.window_ends_us(batch.t_s),
        np.array([p.t_last_us for p in run]),
        np.array([p.sent_ns for p in run]),
    )
