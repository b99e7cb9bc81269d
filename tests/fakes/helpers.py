"""Test helpers around a hardware camera adapter backed by a fake SDK."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from flagtrack.daemon.core.events import empty_events, empty_triggers
from flagtrack.drivers.camera.base import Camera


def read_until(camera: Camera, done: Callable[[], bool], timeout_s: float = 20.0, read_timeout_s: float = 0.01
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """Read until ``done()`` and a read returns None; return (events, triggers, number of non-empty reads)."""
    events, triggers, reads = [empty_events()], [empty_triggers()], 0
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        data = camera.read(read_timeout_s)
        if data is None:
            if done():
                break
            continue
        reads += 1
        events.append(data.events)
        triggers.append(data.triggers)
    else:
        raise AssertionError("the fake camera did not deliver its stream in time")
    return np.concatenate(events), np.concatenate(triggers), reads
