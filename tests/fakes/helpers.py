"""Test helpers: waiting for a condition, reading a hardware camera adapter backed by a fake SDK, and a
rigid flapping flag's centrelines."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.events import empty_events, empty_triggers
from flagtrack.drivers.camera.base import Camera

if TYPE_CHECKING:
    from flagtrack.daemon.transport import Bus


def wait_until(predicate: Callable[[], object], timeout_s: float = 5.0, what: str = "", poll_s: float = 0.01) -> object:
    """Poll ``predicate`` until it returns something true, and return that; after ``timeout_s`` raise
    AssertionError saying ``what`` did not happen (by default, where the predicate is written).

    For tests that wait for something to happen (a thread's result, a subscription reaching the
    other session, a file being written) instead of sleeping a fixed time and hoping.
    """
    deadline = time.monotonic() + timeout_s
    while not (result := predicate()):
        if time.monotonic() >= deadline:
            if not what:
                code = getattr(predicate, "__code__", None)
                what = f"the condition at {code.co_filename}:{code.co_firstlineno}" if code else repr(predicate)
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(poll_s)
    return result


def wait_subscribed(bus: Bus, *keys: str, timeout_s: float = 10.0) -> None:
    """Wait until ``bus``'s session knows a subscriber for each key: what it publishes there from now on
    is delivered (Zenoh drops samples put before a remote subscription has reached the publisher)."""
    for key in keys:
        probe = bus.session.declare_publisher(key)
        try:
            wait_until(lambda p=probe: p.matching_status.matching, timeout_s, f"a subscriber of {key} to reach us")
        finally:
            probe.undeclare()


def read_until(
    camera: Camera, done: Callable[[], bool], timeout_s: float = 20.0, read_timeout_s: float = 0.01
) -> tuple[np.ndarray, np.ndarray, int]:
    """Read until ``done()`` and a read returns None; return (events, triggers, number of non-empty reads).

    An adapter that hands over the device's own bytes (``CameraData.raw``: EVT 3.0/2.0) has them
    decoded here, in one stream, as the tracker decodes its packets.
    """
    events, triggers, reads = [empty_events()], [empty_triggers()], 0
    decoder = None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        data = camera.read(read_timeout_s)
        if data is None:
            if done():
                break
            continue
        reads += 1
        if data.raw is not None:
            if decoder is None:
                from flagtrack.drivers.formats import make_decoder

                decoder = make_decoder(camera._stream.published, strict=True)  # type: ignore[attr-defined]
            decoded_events, decoded_triggers = decoder.decode(data.raw)
            events.append(decoded_events)
            triggers.append(decoded_triggers)
            continue
        events.append(data.events)
        triggers.append(data.triggers)
    else:
        raise AssertionError("the fake camera did not deliver its stream in time")
    return np.concatenate(events), np.concatenate(triggers), reads


def rigid_flapping(t_s: np.ndarray, length: float = 100.0, **flags: np.ndarray) -> CentrelineBatch:
    """A rigid flag of ``length`` rooted at (0, 0), flapping at 10 Hz (A/L = 0.2), at the times ``t_s``;
    ``flags``: its ``lost``, ``stale`` or ``shed`` arrays."""
    theta = 0.2 * np.sin(2 * np.pi * 10 * np.asarray(t_s))[:, None]
    s = np.linspace(0, length, 11)[None, :]
    x, y = s * np.cos(theta), s * np.sin(theta)
    n = len(t_s)
    return CentrelineBatch(t_s, s[0], x, y, x, y, np.full(n, 1.0), np.full(n, 50), **flags)
