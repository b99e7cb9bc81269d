"""Gather a point's sensor data from bus messages, and the camera's trigger events from its raw file."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.core.events import empty_triggers
from flagtrack.daemon.schema import SensorSamples
from flagtrack.drivers.sensor.record import SensorRecord

log = logging.getLogger(__name__)


def record_from_messages(
    messages: Sequence[SensorSamples], camera_wall: Sequence[tuple[int, int]] = (), config: dict[str, Any] | None = None
) -> SensorRecord:
    """One :class:`SensorRecord` of the messages received during a point.

    Args:
        messages: the sensor's messages in arrival order.
        camera_wall: (camera time µs, wall time ns) pairs of the camera's data (centreline updates).
        config: the sensor config, stored with the record.
    """
    ints = np.zeros(0, dtype=np.int64)
    first = messages[0] if messages else None
    stamped = [m for m in messages if len(m.t_us) and m.wall_ns]
    pairs = np.asarray(camera_wall, dtype=np.int64).reshape(-1, 2)
    return SensorRecord(
        sensor_id=first.sensor_id if first else "",
        units=first.units if first else "",
        clock=first.clock if first else "sensor",
        t_us=np.concatenate([ints, *[m.t_us.astype(np.int64) for m in messages]]),
        value=np.concatenate([np.zeros(0), *[m.value.astype(np.float64) for m in messages]]),
        trigger_t_us=np.concatenate([ints, *[m.trigger_t_us.astype(np.int64) for m in messages]]),
        missing=int(sum(m.missing for m in messages)),
        wall_t_us=np.array([int(m.t_us[-1]) for m in stamped], dtype=np.int64),
        wall_ns=np.array([m.wall_ns for m in stamped], dtype=np.int64),
        camera_t_us=pairs[:, 0].copy(),
        camera_wall_ns=pairs[:, 1].copy(),
        config=dict(config or {}),
    )


def raw_triggers(path: str | Path) -> np.ndarray:
    """Every trigger event of an event file (streamed: the events themselves are not kept)."""
    from flagtrack.drivers.formats import open_events

    parts = []
    with open_events(path) as reader:
        for chunk in reader:
            if len(chunk.triggers):
                parts.append(chunk.triggers)
    return np.concatenate(parts) if parts else empty_triggers()
