"""The background-activity filter's parameters, apart from its compiled kernels (a config can be
read without importing numba)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DenoiseParams:
    """Background-activity filter settings.

    Attributes:
        window_us: a neighbour supports an event if it fired within this many µs before it (the
            3x3 neighbourhood; a 5x5 one let more noise through, docs/tracking.md).
        min_neighbours: fewest supporting neighbours an event needs (1: the classic filter).
        max_neighbours: most supporting neighbours the adaptive filter may ask for; equal to
            ``min_neighbours``: a fixed requirement (the classic filter by default).
        noise_pass: adaptive: largest chance that a background event passes, ``C(8, k) (r w)^k``.
        block_us: adaptive: the noise rate is measured over blocks of this many µs (absolute
            event time) and sets the requirement of the next block.
        max_window_us: adaptive: where the noise is sparse enough, the next block's window grows up
            to this (the longest for which a noise event passes one neighbour with at most
            ``noise_pass`` chance), so that the few events of a slowly moving flag pass; 0 (the
            core's default) or ``window_us``: a fixed window.
    """

    window_us: int = 500
    min_neighbours: int = 1
    max_neighbours: int = 1
    noise_pass: float = 0.03
    block_us: int = 2_000
    max_window_us: int = 0

    def __post_init__(self) -> None:
        if not 0 < self.window_us <= 1 << 29:
            raise ValueError(f"window_us must be in (0, 2^29] us, got {self.window_us}")
        if not 1 <= self.min_neighbours <= self.max_neighbours <= 8:
            raise ValueError(
                f"need 1 <= min_neighbours <= max_neighbours <= 8, got {self.min_neighbours}, {self.max_neighbours}"
            )
        if not 0 < self.noise_pass < 1:
            raise ValueError(f"noise_pass must be in (0, 1), got {self.noise_pass}")
        if self.block_us <= 0:
            raise ValueError(f"block_us must be positive, got {self.block_us}")
        if self.max_window_us != 0 and not self.window_us <= self.max_window_us <= 1 << 29:
            raise ValueError(f"max_window_us must be 0 or in [window_us, 2^29] us, got {self.max_window_us}")

    @property
    def longest_window_us(self) -> int:
        """The longest support window the adaptive rule may use (``window_us`` when fixed)."""
        return max(self.window_us, self.max_window_us)

    def thresholds(self) -> np.ndarray:
        """(9,) float64: ``C(8, k)`` for k = 0..8 (the adaptive rule's binomial factors)."""
        return np.array([math.comb(8, k) for k in range(9)], dtype=np.float64)
