"""Scenes the simulated event camera looks at, and the loop that turns a scene into event chunks.

A scene implements :class:`Scene`: ``start(camera, t_us)`` resets the camera to the first image,
``advance(camera, t_us)`` feeds it the intensity changes up to ``t_us``. Two scenes exist: the
laser line on a flapping flag (:class:`~flagtrack.drivers.sim.render.LaserLineScene`) and a
blinking checkerboard on the plane (:class:`BlinkingPatternScene` with :func:`checkerboard`) for
calibration. :func:`simulate_events` drives any scene and yields time-sorted event arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from typing import Protocol

import numpy as np

from flagtrack.drivers.sim.dvs import DvsParams, EventCamera
from flagtrack.drivers.sim.optics import PlaneCamera

PlanePattern = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""Intensity in [0, 1] of the plane at points (x, y) (arrays of one shape), plane units."""


class Scene(Protocol):
    """Something an :class:`EventCamera` can look at."""

    width: int
    height: int

    def start(self, camera: EventCamera, t_us: int) -> None:
        """Reset ``camera`` to the scene at ``t_us``."""
        ...

    def advance(self, camera: EventCamera, t_us: int) -> None:
        """Feed ``camera`` the changes from the last time to ``t_us``."""
        ...


@dataclass(frozen=True)
class CheckerboardSpec:
    """A checkerboard on the plane.

    Attributes:
        inner_corners: (n, m) inner corners along x and y (the board has n+1 by m+1 squares).
        square: side of one square, plane units (m for a tilted camera).
        origin: plane position of the first inner corner.
    """

    inner_corners: tuple[int, int] = (9, 6)
    square: float = 0.02
    origin: tuple[float, float] = (0.0, -0.05)

    def corners(self) -> np.ndarray:
        """(n*m, 2) plane positions of the inner corners, x fastest."""
        n, m = self.inner_corners
        gx, gy = np.meshgrid(np.arange(n), np.arange(m))
        return np.column_stack([self.origin[0] + gx.ravel() * self.square, self.origin[1] + gy.ravel() * self.square])


def checkerboard(spec: CheckerboardSpec) -> PlanePattern:
    """Pattern function of ``spec``: 1 on white squares, 0 on black squares and off the board."""
    n, m = spec.inner_corners

    def pattern(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        i = np.floor((np.asarray(x) - spec.origin[0]) / spec.square) + 1  # square column, 0..n
        j = np.floor((np.asarray(y) - spec.origin[1]) / spec.square) + 1
        on_board = (i >= 0) & (i <= n) & (j >= 0) & (j <= m)
        return np.where(on_board & ((i + j) % 2 == 0), 1.0, 0.0)

    return pattern


@dataclass(frozen=True)
class BlinkParams:
    """Blinking of a pattern shown on a screen.

    Attributes:
        period_us: blink period (on for half of it, off for the other half).
        ramp_us: duration of each switch (intensity linear in time).
        background: intensity of dark parts and of the switched-off screen.
        peak: intensity added on white squares when the screen is on.
        supersample: sub-pixel samples per axis when evaluating the pattern (anti-aliasing).
        ramp_steps: render steps per switch.
    """

    period_us: int = 100_000
    ramp_us: int = 500
    background: float = 0.1
    peak: float = 1.0
    supersample: int = 3
    ramp_steps: int = 8

    def to_attrs(self) -> dict[str, float]:
        """Parameters as a flat mapping."""
        return asdict(self)


class BlinkingPatternScene:
    """A plane pattern (e.g. :func:`checkerboard`) on a screen that blinks, seen through ``optics``."""

    def __init__(
        self, pattern: PlanePattern, optics: PlaneCamera, width: int, height: int, blink: BlinkParams = BlinkParams()
    ) -> None:
        self.optics, self.blink, self.width, self.height = optics, blink, width, height
        k = blink.supersample
        offsets = (np.arange(k) + 0.5) / k - 0.5
        vv, uu = np.mgrid[0:height, 0:width].astype(np.float64)
        total = np.zeros((height, width))
        for du in offsets:
            for dv in offsets:
                x, y = optics.unproject(uu + du, vv + dv)
                total += pattern(x, y)
        self.white = (total / k**2).ravel()
        self.lit = np.flatnonzero(self.white > 0)
        self.t_us = 0.0

    def screen_on(self, t_us: float) -> float:
        """Screen brightness factor in [0, 1] at ``t_us`` (on during the first half period)."""
        b = self.blink
        phase = t_us % b.period_us
        half = b.period_us / 2
        if phase < b.ramp_us:
            return phase / b.ramp_us
        if phase < half:
            return 1.0
        if phase < half + b.ramp_us:
            return 1.0 - (phase - half) / b.ramp_us
        return 0.0

    def _levels(self, t_us: float, log_eps: float) -> np.ndarray:
        b = self.blink
        return np.log(b.background + b.peak * self.screen_on(t_us) * self.white[self.lit] + log_eps)

    def start(self, camera: EventCamera, t_us: int) -> None:
        """Reset ``camera`` to the pattern at ``t_us``."""
        image = np.full(self.width * self.height, math.log(self.blink.background + camera.params.log_eps))
        image[self.lit] = self._levels(t_us, camera.params.log_eps)
        camera.reset(image, t_us)
        self.t_us = float(t_us)

    def advance(self, camera: EventCamera, t_us: int) -> None:
        """Feed the switches between the last time and ``t_us`` (steps only inside ramps)."""
        b = self.blink
        first = math.floor(self.t_us / (b.period_us / 2))
        steps = [float(t_us)]
        for edge in range(first, math.floor(t_us / (b.period_us / 2)) + 1):
            start = edge * b.period_us / 2
            steps.extend(start + b.ramp_us * np.arange(b.ramp_steps + 1) / b.ramp_steps)
        steps = sorted(t for t in set(steps) if self.t_us < t <= t_us)
        for t in steps:
            camera.advance(self.lit, self._levels(t, camera.params.log_eps), t)
        self.t_us = float(t_us)


def simulate_events(
    scene: Scene,
    t_start_us: int,
    t_stop_us: int,
    dvs: DvsParams = DvsParams(),
    seed: int = 0,
    chunk_us: int = 10_000,
) -> Iterator[np.ndarray]:
    """Yield time-sorted event arrays covering [t_start_us, t_stop_us), one per ``chunk_us``.

    Line events, leak events (every pixel flushed at each chunk end) and shot noise are merged.
    """
    camera = EventCamera(scene.width, scene.height, dvs, seed)
    scene.start(camera, t_start_us)
    for chunk_start in range(t_start_us, t_stop_us, chunk_us):
        chunk_stop = min(chunk_start + chunk_us, t_stop_us)
        scene.advance(camera, chunk_stop)
        camera.flush(chunk_stop)
        events = np.concatenate([camera.take(), camera.shot_noise(chunk_start, chunk_stop)])
        events = events[events["t"] < chunk_stop]
        yield events[np.argsort(events["t"], kind="stable")]
