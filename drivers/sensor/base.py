"""The point-sensor interface every driver implements, and what it yields."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np


@dataclass(frozen=True)
class SensorInfo:
    """What an opened sensor reports.

    Attributes:
        driver: ``ascii``, ``modbus`` or ``simulated``.
        device: port or description, for messages.
        units: unit of the readings (``mm``, ``px``, ...).
        clock: ``sensor`` (samples stamped by the device's clock) or ``host`` (stamped on arrival,
            wall-clock µs).
        rate_hz: nominal sample rate.
        settings: what the driver was configured with (stored beside the samples).
    """

    driver: str
    device: str
    units: str
    clock: Literal["sensor", "host"]
    rate_hz: float
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SensorReading:
    """Samples gathered by one :meth:`PointSensor.read`.

    Attributes:
        t_us: (n,) int64 sample times on the sensor clock, µs.
        value: (n,) float64 readings in sensor units; NaN = missing (no reply, out of range).
        trigger_t_us: (m,) int64 trigger pulses the sensor drove or recorded, sensor clock, µs.
        missing: samples lost in this read (its NaN values included).
        wall_ns: wall time (ns) the newest sample arrived.
    """

    t_us: np.ndarray
    value: np.ndarray
    trigger_t_us: np.ndarray
    missing: int = 0
    wall_ns: int = 0

    def __len__(self) -> int:
        return len(self.t_us)


def reading(
    t_us: Sequence[int] | np.ndarray = (),
    value: Sequence[float] | np.ndarray = (),
    trigger_t_us: Sequence[int] | np.ndarray = (),
    missing: int = 0,
    wall_ns: int | None = None,
) -> SensorReading:
    """Build a :class:`SensorReading` from lists (wall time now unless given)."""
    return SensorReading(
        np.asarray(t_us, dtype=np.int64),
        np.asarray(value, dtype=np.float64),
        np.asarray(trigger_t_us, dtype=np.int64),
        int(missing),
        time.time_ns() if wall_ns is None else int(wall_ns),
    )


class PointSensor(Protocol):
    """A sensor measuring one number (the flag's distance) many times a second."""

    def open(self) -> SensorInfo:
        """Connect and start sampling; return the description."""
        ...

    def read(self, timeout_s: float) -> SensorReading:
        """Samples gathered within about ``timeout_s`` (possibly none). Failed exchanges become NaN
        samples; DriverError only when the sensor has been silent too long (the caller reopens it)."""
        ...

    def close(self) -> None:
        """Stop sampling and release the port (idempotent)."""
        ...


class HostClock:
    """Wall-clock microseconds that never go backwards within a session (monotonic, wall-anchored)."""

    def __init__(self) -> None:
        self._wall0_us = time.time_ns() // 1000
        self._mono0_ns = time.monotonic_ns()

    def now_us(self) -> int:
        """Current time, µs since the epoch."""
        return self._wall0_us + (time.monotonic_ns() - self._mono0_ns) // 1000
