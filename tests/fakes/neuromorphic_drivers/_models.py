"""Configuration dataclasses shared by the fake model modules, shaped like neuromorphic-drivers' generated ones."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass
class RateLimiter:
    reference_period_us: int
    maximum_events_per_period: int

    def serialize(self) -> bytes:
        return repr(self).encode()


@dataclasses.dataclass(frozen=True)
class Bounds:
    minimum: int = 0
    maximum: int = 0


@dataclasses.dataclass
class RingConfiguration:
    buffer_length: int = 131072
    ring_length: int = 4096
    parallel_submissions: int = 32


def check_words(name: str, words: tuple, n: int) -> None:
    """The real serializer refuses masks of the wrong length or out-of-range words."""
    if len(words) != n or any(not 0 <= int(w) < 1 << 64 for w in words):
        raise ValueError(f"{name} must be {n} unsigned 64-bit words")
