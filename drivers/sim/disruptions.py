"""Disruptions of a flapping recording: what makes a tracker lose the flag.

Pure, seeded functions on time-sorted event arrays (``EVENT_DTYPE``), shared by the tests and the
accuracy benchmark: an occlusion (the laser blocked: no event in a time span), an object crossing
the field of view (the events of a moving disc's edge), a bright reflection (a burst of events in
a patch), and a chain started far off the flag (an initial state). :func:`disrupted` applies a
named scenario of :data:`SCENARIOS` and says when the disruptions end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.chain import ChainState
from flagtrack.daemon.core.events import EVENT_DTYPE


def _merge(events: np.ndarray, extra: np.ndarray) -> np.ndarray:
    merged = np.concatenate([events, extra])
    return merged[np.argsort(merged["t"], kind="stable")]


def occlusion(events: np.ndarray, t0_us: int, t1_us: int) -> np.ndarray:
    """Drop every event with ``t0_us <= t < t1_us`` (the laser sheet blocked)."""
    t = events["t"]
    return events[(t < t0_us) | (t >= t1_us)]


@dataclass(frozen=True)
class CrossingObject:
    """A disc of ``radius_px`` moving at constant speed from ``start`` to ``end`` (pixels) during
    ``[t0_us, t1_us)``; its edge makes ``events_per_px2`` events per pixel area it sweeps."""

    t0_us: int
    t1_us: int
    start: tuple[float, float]
    end: tuple[float, float]
    radius_px: float = 25.0
    events_per_px2: float = 20.0

    def events(self, rng: np.random.Generator, width: int, height: int) -> np.ndarray:
        """The object's events, time-sorted (those off the sensor dropped)."""
        duration_s = (self.t1_us - self.t0_us) * 1e-6
        speed = np.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1]) / duration_s
        n = rng.poisson(2 * self.radius_px * speed * duration_s * self.events_per_px2)
        t = np.sort(rng.integers(self.t0_us, self.t1_us, n))
        frac = (t - self.t0_us) / (self.t1_us - self.t0_us)
        cx = self.start[0] + frac * (self.end[0] - self.start[0])
        cy = self.start[1] + frac * (self.end[1] - self.start[1])
        # edge points, denser where the edge moves along its normal (leading and trailing edges)
        heading = np.arctan2(self.end[1] - self.start[1], self.end[0] - self.start[0])
        phi = heading + np.arcsin(rng.uniform(-1.0, 1.0, n)) + np.where(rng.random(n) < 0.5, 0.0, np.pi)
        r = self.radius_px + rng.normal(0.0, 0.8, n)
        out = np.empty(n, dtype=EVENT_DTYPE)
        out["t"] = t
        out["x"] = np.clip(np.rint(cx + r * np.cos(phi)), -1, width).astype(out["x"].dtype)
        out["y"] = np.clip(np.rint(cy + r * np.sin(phi)), -1, height).astype(out["y"].dtype)
        out["p"] = rng.integers(0, 2, n)
        on = (out["x"] >= 0) & (out["x"] < width) & (out["y"] >= 0) & (out["y"] < height)
        return out[on]


def crossing(
    events: np.ndarray, obj: CrossingObject, rng: np.random.Generator, width: int = 640, height: int = 480
) -> np.ndarray:
    """Add the events of ``obj`` crossing the field of view."""
    return _merge(events, obj.events(rng, width, height))


def reflection(
    events: np.ndarray,
    t0_us: int,
    t1_us: int,
    centre: tuple[float, float],
    half_size_px: float,
    n_events: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """Add a burst of ``n_events`` uniform in the square patch of ``half_size_px`` around ``centre``
    during ``[t0_us, t1_us)`` (a sudden bright reflection)."""
    burst = np.empty(n_events, dtype=EVENT_DTYPE)
    burst["t"] = np.sort(rng.integers(t0_us, t1_us, n_events))
    burst["x"] = np.maximum(np.rint(centre[0] + rng.uniform(-half_size_px, half_size_px, n_events)), 0)
    burst["y"] = np.maximum(np.rint(centre[1] + rng.uniform(-half_size_px, half_size_px, n_events)), 0)
    burst["p"] = rng.integers(0, 2, n_events)
    return _merge(events, burst)


def background(events: np.ndarray, n_events: int, rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Add ``n_events`` at uniform random times (over the events' span), pixels and polarities."""
    noise = np.empty(n_events, dtype=EVENT_DTYPE)
    noise["t"] = rng.integers(int(events["t"][0]), int(events["t"][-1]) + 1, n_events)
    noise["x"] = rng.integers(0, width, n_events)
    noise["y"] = rng.integers(0, height, n_events)
    noise["p"] = rng.integers(0, 2, n_events)
    return _merge(events, noise)


def rotated_start(state: ChainState, offset_deg: float) -> ChainState:
    """``state`` with every link turned by ``offset_deg`` about the root (a chain started off)."""
    return ChainState(np.asarray(state.angles_rad, dtype=np.float64) + np.deg2rad(offset_deg))


@dataclass(frozen=True)
class Scenario:
    """A disrupted recording: the flag's events changed, the initial chain turned.

    Attributes:
        name: the scenario's name (:data:`SCENARIOS`).
        events: the events.
        start_offset_deg: turn of the initial chain about the root, degrees.
        spans_us: (start, end) µs of each disruption (the initial offset: (first event, first event)).
    """

    name: str
    events: np.ndarray
    start_offset_deg: float
    spans_us: tuple[tuple[int, int], ...]


SCENARIOS = ("clean", "noisy", "occlusion", "crossing", "reflection", "blackout+crossing", "start-90")
"""Scenario names, each on a recording of at least 0.5 s (10 periods at 20 Hz)."""


def disrupted(
    name: str,
    events: np.ndarray,
    root: tuple[float, float],
    length: float,
    direction_deg: float = 0.0,
    seed: int = 0,
    width: int = 640,
    height: int = 480,
) -> Scenario:
    """Apply scenario ``name`` to a flapping recording of a flag of ``length`` (pixels) at ``root``
    whose rest direction is ``direction_deg``.

    Times are relative to the first event; places are along the rest line (a L) and across it (b L):
    ``occlusion``: no events for 100 ms from 150 ms; ``crossing``: a disc of 0.125 L radius crosses
    the flag at a = 0.6, from b = -1 to b = 1, in 150 ms from 150 ms; ``reflection``: 20 000 events
    in a square of 0.15 L at a = 0.8, b = 0.25, for 20 ms from 150 ms; ``blackout+crossing``: the
    issue's case, 100 ms blocked from 150 ms then the crossing from 300 ms; ``start-90``: the chain
    starts 90 degrees off; ``noisy``: uniform background events, twice as many as the recording's
    (the paper's N/N0 = 3, f_snr/f = 74), no disruption; ``clean``: nothing.
    """
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r} (one of {', '.join(SCENARIOS)})")
    rng = np.random.default_rng([seed, SCENARIOS.index(name)])
    t0 = int(events["t"][0])
    ms = 1000
    ux, uy = np.cos(np.deg2rad(direction_deg)), np.sin(np.deg2rad(direction_deg))

    def at(a: float, b: float) -> tuple[float, float]:
        return (root[0] + length * (a * ux - b * uy), root[1] + length * (a * uy + b * ux))

    def cross(start_us: int) -> tuple[np.ndarray, tuple[int, int]]:
        obj = CrossingObject(start_us, start_us + 150 * ms, at(0.6, -1.0), at(0.6, 1.0), radius_px=0.125 * length)
        return crossing(events, obj, rng, width, height), (start_us, start_us + 150 * ms)

    offset = 0.0
    spans: tuple[tuple[int, int], ...] = ()
    if name == "occlusion":
        events, spans = occlusion(events, t0 + 150 * ms, t0 + 250 * ms), ((t0 + 150 * ms, t0 + 250 * ms),)
    elif name == "crossing":
        events, span = cross(t0 + 150 * ms)
        spans = (span,)
    elif name == "reflection":
        span = (t0 + 150 * ms, t0 + 170 * ms)
        events, spans = reflection(events, *span, at(0.8, 0.25), 0.075 * length, 20_000, rng), (span,)
    elif name == "blackout+crossing":
        events = occlusion(events, t0 + 150 * ms, t0 + 250 * ms)
        events, span = cross(t0 + 300 * ms)
        spans = ((t0 + 150 * ms, t0 + 250 * ms), span)
    elif name == "start-90":
        offset, spans = 90.0, ((t0, t0),)
    elif name == "noisy":
        events = background(events, 2 * len(events), rng, width, height)
    return Scenario(name, events, offset, spans)
