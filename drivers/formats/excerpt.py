"""The first seconds of an event file, time-sorted, with the sensor size (a calibration board's recording)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from flagtrack.daemon.core.events import empty_events
from flagtrack.daemon.errors import FormatError

log = logging.getLogger(__name__)


def read_excerpt(
    path: str | Path, max_s: float | None = 10.0, size: tuple[int, int] | None = None
) -> tuple[np.ndarray, tuple[int, int]]:
    """Events of the first ``max_s`` seconds of ``path`` (any event file flagtrack reads), and the sensor size.

    Args:
        path: event file.
        max_s: keep events up to this long after the first one (None: all).
        size: (width, height) if the file does not give it (default: the file's, else max x/y + 1).

    Raises:
        FormatError: the file cannot be decoded, or holds no events.
    """
    from flagtrack.drivers.formats import open_events

    parts: list[np.ndarray] = []
    with open_events(path) as reader:
        info = reader.info
        t_end = None
        for chunk in reader:
            events = chunk.events
            if not len(events):
                continue
            if t_end is None and max_s is not None:
                t_end = int(events["t"][0]) + int(max_s * 1e6)
            if t_end is not None and events["t"][0] > t_end:
                break
            parts.append(events if t_end is None else events[events["t"] <= t_end])
    events = np.concatenate(parts) if parts else empty_events()
    if not len(events):
        raise FormatError("no events in the recording", path=str(path))
    if np.any(np.diff(events["t"]) < 0):
        events = events[np.argsort(events["t"], kind="stable")]
    if size is None:
        if info.width and info.height:
            size = (int(info.width), int(info.height))
        else:
            size = (int(events["x"].max()) + 1, int(events["y"].max()) + 1)
            log.warning("%s does not give the sensor size: using %dx%d from the events", path, *size)
    return events, size
