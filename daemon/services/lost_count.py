"""Counts of lost updates and lost stretches over a service's life (the tracker's status)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LostCount:
    """Updates whose ``lost`` is 1, and stretches of consecutive ones, across batches and streams."""

    updates: int = 0
    stretches: int = 0
    _last: int = 0

    def add(self, lost: np.ndarray) -> None:
        """Count the (n_t,) ``lost`` flags of the next updates, in order."""
        if len(lost) == 0:
            return
        if not lost.any():  # the usual case: nothing to count (spares the arrays below)
            self._last = 0
            return
        flags = np.asarray(lost, dtype=np.int8)
        self.updates += int(flags.sum())
        self.stretches += int(np.count_nonzero(np.diff(flags, prepend=np.int8(self._last)) == 1))
        self._last = int(flags[-1])

    def end_stream(self) -> None:
        """A stream ended: a lost update at the start of the next one begins a new stretch."""
        self._last = 0
