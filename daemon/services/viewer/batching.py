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


@dataclass
class UpdateSlots:
    """Which tracker updates the view shows: the first of each ``1 / rate_hz`` slot of camera time
    (None: every one). The slot of the last update shown carries over from one message to the next,
    so the choice does not depend on how the updates were batched."""

    rate_hz: float | None
    last_slot: float = float("nan")

    def keep(self, t_s: Any) -> Any:
        """(n,) bool: the updates at ``t_s`` (s, (n,)) that open a new slot."""
        import numpy as np

        t_s = np.asarray(t_s, dtype=np.float64)
        if self.rate_hz is None:
            return np.isfinite(t_s)
        slots = np.floor(t_s * self.rate_hz + 1e-6)  # (a time a rounding below a slot's start opens it)
        finite = np.isfinite(slots)
        shown = slots[finite]
        if not len(shown):
            return finite
        before = np.concatenate([[self.last_slot], shown[:-1]])
        keep = np.zeros(len(t_s), dtype=bool)
        keep[finite] = shown != before  # a new slot (or a camera clock that went back)
        self.last_slot = float(shown[-1])
        return keep


def changes(values: Any, before: float) -> Any:
    """(n,) bool: where ``values`` differ from the value before them (``before`` for the first)."""
    import numpy as np

    values = np.asarray(values, dtype=np.float64)
    return values != np.concatenate([[before], values[:-1]])
