"""Rows waiting to be sent to Rerun, one queue per entity, and when a queue is sent (no rerun here).

Every row Rerun receives alone becomes a chunk of its own in an .rrd file (Rerun's file sink does not
merge them), and a file of thousands of tiny chunks is slow to open and query ("may be unoptimized",
says ``rerun rrd stats``). So the viewer queues rows per entity and sends each queue in one
``send_columns`` call when :meth:`FlushPolicy.due` says so: soon for a live viewer, in large chunks
for a file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class RowQueue:
    """The rows of one entity waiting to be sent: pieces (whatever the entity's sender takes), their
    row and byte counts, when the oldest of them was queued (``since_s``, None: not yet noted), and
    the most rows one chunk of this entity should hold (``max_rows``, None: the policy's)."""

    pieces: list[Any] = field(default_factory=list)
    n_rows: int = 0
    n_bytes: int = 0
    since_s: float | None = None
    max_rows: int | None = None

    def add(self, piece: Any, n_rows: int, n_bytes: int) -> None:
        """Queue ``piece`` of ``n_rows`` rows, about ``n_bytes`` once sent."""
        self.pieces.append(piece)
        self.n_rows += n_rows
        self.n_bytes += n_bytes

    def take(self) -> list[Any]:
        """The queued pieces, oldest first; the queue is empty afterwards."""
        pieces, self.pieces = self.pieces, []
        self.n_rows = self.n_bytes = 0
        self.since_s = None
        return pieces


@dataclass(frozen=True)
class FlushPolicy:
    """When a queue is sent: it holds ``chunk_bytes`` or ``chunk_rows`` (or its own ``max_rows``), or its
    oldest row has waited ``interval_s`` (0.25 s for a live viewer, tens of seconds for a file).

    Rerun's offline optimiser (``rerun rrd optimize``, object-store profile) aims at chunks of up to
    2 MiB and about 65 000 rows, and ``rerun rrd stats`` counts the fewest chunks the data could fit
    in at that size: a file whose busy entities are sent at ``chunk_bytes`` = 2 MiB and whose quiet
    ones every ``interval_s`` stays within a few times that bound.
    """

    interval_s: float
    chunk_bytes: int = 2 << 20
    chunk_rows: int = 32_768

    def due(self, queue: RowQueue, now_s: float) -> bool:
        """Whether ``queue`` is to be sent at ``now_s`` (seconds of the clock ``since_s`` is on)."""
        if not queue.n_rows:
            return False
        max_rows = self.chunk_rows if queue.max_rows is None else min(queue.max_rows, self.chunk_rows)
        if queue.n_bytes >= self.chunk_bytes or queue.n_rows >= max_rows:
            return True
        return queue.since_s is not None and now_s - queue.since_s >= self.interval_s
