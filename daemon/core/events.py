"""The event array type shared by every part of flagtrack.

Events are one numpy structured array of :data:`EVENT_DTYPE`: ``t`` int64 microseconds,
``x``/``y`` uint16 pixel (or the integer column/row of the sensor), ``p`` uint8 with 1 = ON.
External-trigger events are kept apart in :data:`TRIGGER_DTYPE` arrays.
"""

from __future__ import annotations

import numpy as np

EVENT_DTYPE = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
"""Camera change-detection events: t µs, x/y pixel, p 1 = ON (brighter), 0 = OFF."""

MAX_SENSOR_PX = 8192
"""No event sensor is wider or taller (the largest are 1280 x 960): a size or pixel beyond is not an event recording's."""


def beyond_any_sensor(x: int, y: int) -> str:
    """What an event at pixel (``x``, ``y``), beyond :data:`MAX_SENSOR_PX`, says of its file."""
    return (
        f"an event at pixel ({x}, {y}): beyond any event sensor ({MAX_SENSOR_PX} pixels a side at most): "
        "not an event recording, or a corrupt one"
    )


TRIGGER_DTYPE = np.dtype([("t", "<i8"), ("channel", "u1"), ("edge", "u1")])
"""External trigger events: t µs, input channel, edge 1 = rising, 0 = falling."""


def empty_events(n: int = 0) -> np.ndarray:
    """Return a zeroed event array of length ``n``."""
    return np.zeros(n, dtype=EVENT_DTYPE)


def empty_triggers(n: int = 0) -> np.ndarray:
    """Return a zeroed trigger array of length ``n``."""
    return np.zeros(n, dtype=TRIGGER_DTYPE)


def make_events(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Pack four equal-length columns into an event array (values are cast, not checked)."""
    events = np.empty(len(t_us), dtype=EVENT_DTYPE)
    events["t"] = t_us
    events["x"] = x
    events["y"] = y
    events["p"] = p
    return events
