"""What ``flagtrack aim`` measures while a camera is set up: the events of the last ``window_ms`` as an
image, the event rate, hot pixels and the laser line's width (:mod:`.line_width`).

:class:`AimAccumulator` takes the camera's events as they come (camera time order) and keeps two
things: the events of the last ``window_ms`` (their times and pixels), and per-pixel counts in bins
of ``bin_ms`` over the last ``rate_window_s`` (no events kept), from which the rate and the hot
pixels come. :meth:`AimAccumulator.frame` draws it all into one :class:`AimFrame`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from flagtrack.daemon.core.line_width import LineWidth, LineWidthParams, measure_line_width

#: Offsets (dy, dx) of the 24 other pixels of a pixel's 5x5 neighbourhood.
NEIGHBOURS = tuple((dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if (dy, dx) != (0, 0))


@dataclass(frozen=True)
class HotPixelParams:
    """What makes a pixel hot.

    Attributes:
        factor: it fires at least this many times as often as the second-busiest other pixel of its
            5x5 neighbourhood (plus one event): a pixel of a line, even at its end, has at least two
            busy neighbours along it, a hot pixel none (or one, for a pair of hot pixels).
        min_rate_hz: and at least this often.
    """

    factor: float = 10.0
    min_rate_hz: float = 20.0

    def __post_init__(self) -> None:
        if not (self.factor > 1 and math.isfinite(self.factor)):
            raise ValueError(f"factor must be more than 1, got {self.factor}")
        if not (self.min_rate_hz > 0 and math.isfinite(self.min_rate_hz)):
            raise ValueError(f"min_rate_hz must be positive, got {self.min_rate_hz}")


@dataclass(frozen=True)
class HotPixels:
    """Hot pixels, busiest first: (n,) arrays of column, row, rate and the reference neighbour's rate."""

    x: np.ndarray
    y: np.ndarray
    rate_hz: np.ndarray
    neighbour_rate_hz: np.ndarray

    def __len__(self) -> int:
        return len(self.x)


def neighbour_reference(counts: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(n,) the count of the second-busiest other pixel of the 5x5 neighbourhood of each pixel (rows,
    cols) of ``counts`` (pixels beyond the edge count 0)."""
    padded = np.pad(counts, 2)
    around = np.stack([padded[rows + 2 + dy, cols + 2 + dx] for dy, dx in NEIGHBOURS])
    return np.partition(around, len(NEIGHBOURS) - 2, axis=0)[len(NEIGHBOURS) - 2]


def find_hot_pixels(counts: np.ndarray, span_s: float, params: HotPixelParams = HotPixelParams()) -> HotPixels:
    """The hot pixels of per-pixel event ``counts`` (height, width) collected over ``span_s`` seconds."""
    if span_s <= 0:
        empty = np.zeros(0)
        return HotPixels(empty.astype(np.int64), empty.astype(np.int64), empty, empty)
    min_count = max(2.0, params.min_rate_hz * span_s)
    rows, cols = np.nonzero(counts >= min_count)
    values = counts[rows, cols].astype(np.float64)
    reference = neighbour_reference(counts, rows, cols).astype(np.float64)
    hot = values >= params.factor * (reference + 1.0)
    rows, cols, values, reference = rows[hot], cols[hot], values[hot], reference[hot]
    order = np.lexsort((cols, rows, -values))
    return HotPixels(cols[order], rows[order], values[order] / span_s, reference[order] / span_s)


def without_hot_pixels(image: np.ndarray, hot: HotPixels) -> np.ndarray:
    """A float copy of ``image`` whose hot pixels hold their reference neighbour's value."""
    clean = image.astype(np.float64)
    if len(hot):
        clean[hot.y, hot.x] = neighbour_reference(clean, hot.y, hot.x)
    return clean


def display_levels(image: np.ndarray, hot: HotPixels, percentile: float = 99.0) -> np.ndarray:
    """(height, width) uint8 grey levels of an image of counts for the eye: hot pixels left out, the
    ``percentile`` of the counted pixels white, a square-root ramp below it (faint events stay visible)."""
    clean = without_hot_pixels(image, hot)
    counted = clean[clean > 0]
    if not len(counted):
        return np.zeros(image.shape, dtype=np.uint8)
    top = max(float(np.percentile(counted, percentile)), 1.0)
    return (255 * np.sqrt(np.clip(clean / top, 0.0, 1.0))).round().astype(np.uint8)


@dataclass(frozen=True)
class AimParams:
    """Settings of :class:`AimAccumulator`.

    Attributes:
        width, height: sensor size, pixels.
        window_ms: the image holds the events of the last this many ms.
        rate_window_s: the rate and the hot pixels are taken over the last this many seconds.
        bin_ms: per-pixel counts are kept in bins of this much camera time (the rate window moves by it).
        hot: hot-pixel detection.
        line: line-width measurement.
    """

    width: int
    height: int
    window_ms: float = 10.0
    rate_window_s: float = 1.0
    bin_ms: float = 100.0
    hot: HotPixelParams = field(default_factory=HotPixelParams)
    line: LineWidthParams = field(default_factory=LineWidthParams)

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"sensor size must be positive, got {self.width}x{self.height}")
        for name in ("window_ms", "rate_window_s", "bin_ms"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.bin_ms > self.rate_window_s * 1e3:
            raise ValueError(f"bin_ms ({self.bin_ms}) must not exceed the rate window ({self.rate_window_s} s)")


@dataclass(frozen=True)
class AimFrame:
    """What the camera saw up to ``t_end_us``.

    Attributes:
        t_end_us: the stream is complete before this camera time.
        window_us: ``image`` holds the events of ``[t_end_us - window_us, t_end_us)``.
        image: (height, width) uint32 event counts per pixel (hot pixels included).
        rate_hz: events per second over ``rate_span_s`` (the last ``rate_window_s``, or less at the start).
        rate_span_s: the time the rate and the hot pixels are taken over.
        hot: hot pixels over ``rate_span_s``.
        line: the line's width in ``image`` (hot pixels left out).
        n_events: events taken in since the start (inside the sensor).
        n_outside: events dropped for being outside the sensor.
    """

    t_end_us: int
    window_us: int
    image: np.ndarray
    rate_hz: float
    rate_span_s: float
    hot: HotPixels
    line: LineWidth
    n_events: int
    n_outside: int


class AimAccumulator:
    """The camera's recent events, for :class:`AimFrame` s (see the module docstring).

    Events that come later than newer ones (out of camera time order) count in the open bin.
    """

    def __init__(self, params: AimParams) -> None:
        self.params = params
        self.window_us = max(1, round(params.window_ms * 1e3))
        self.bin_us = max(1, round(params.bin_ms * 1e3))
        self.n_bins = max(1, math.ceil(params.rate_window_s * 1e6 / self.bin_us))
        self._n_pixels = params.width * params.height
        self._recent: deque[tuple[int, np.ndarray, np.ndarray]] = deque()  # (latest t, t, flat pixel)
        self._closed: deque[tuple[int, np.ndarray | None, int]] = deque()  # (bin, counts, n)
        self._total = np.zeros(self._n_pixels, dtype=np.int64)  # counts of the closed bins held
        self._open_bin: int | None = None
        self._open: list[np.ndarray] = []  # flat pixels of the open bin
        self._open_n = 0
        self.t_first_us: int | None = None
        self.t_end_us: int | None = None
        self.n_events = 0
        self.n_outside = 0

    def push(self, events: np.ndarray, t_until_us: int | None = None) -> None:
        """Take the next events (EVENT_DTYPE); ``t_until_us``: the stream is complete before this time."""
        inside = (events["x"] < self.params.width) & (events["y"] < self.params.height)
        if not inside.all():
            self.n_outside += int(len(events) - np.count_nonzero(inside))
            events = events[inside]
        t_end = self.t_end_us
        if len(events):
            t = events["t"].astype(np.int64)
            t_max = int(t.max())
            t_end = t_max + 1 if t_end is None else max(t_end, t_max + 1)
            self.t_first_us = int(t.min()) if self.t_first_us is None else min(self.t_first_us, int(t.min()))
        if t_until_us is not None:
            t_end = int(t_until_us) if t_end is None else max(t_end, int(t_until_us))
        if t_end is None:
            return
        self.t_end_us = t_end
        self._advance((t_end - 1) // self.bin_us)
        if len(events):
            flat = events["y"].astype(np.int64) * self.params.width + events["x"]
            self._recent.append((t_max, t, flat))
            self._open.append(flat)
            self._open_n += len(flat)
            self.n_events += len(flat)
        while self._recent and self._recent[0][0] < t_end - self.window_us:
            self._recent.popleft()

    def window_image(self) -> np.ndarray:
        """(height, width) uint32: events of ``[t_end_us - window_us, t_end_us)`` per pixel."""
        shape = (self.params.height, self.params.width)
        if not self._recent or self.t_end_us is None:
            return np.zeros(shape, dtype=np.uint32)
        t = np.concatenate([piece[1] for piece in self._recent])
        flat = np.concatenate([piece[2] for piece in self._recent])
        take = t >= self.t_end_us - self.window_us
        counts = np.bincount(flat[take], minlength=self._n_pixels)
        return counts.astype(np.uint32).reshape(shape)

    def pixel_counts(self) -> tuple[np.ndarray, int, float]:
        """((height, width) int64 events per pixel, their number, the span in s) over the rate window."""
        shape = (self.params.height, self.params.width)
        if self.t_end_us is None or self._open_bin is None or self.t_first_us is None:
            return np.zeros(shape, dtype=np.int64), 0, 0.0
        counts = self._total.copy()
        if self._open:
            counts += np.bincount(np.concatenate(self._open), minlength=self._n_pixels)
        n = self._open_n + sum(entry[2] for entry in self._closed)
        start_us = max((self._open_bin - self.n_bins + 1) * self.bin_us, self.t_first_us)
        return counts.reshape(shape), n, max(0, self.t_end_us - start_us) * 1e-6

    def frame(self) -> AimFrame:
        """Everything measured up to now."""
        image = self.window_image()
        counts, n, span_s = self.pixel_counts()
        hot = find_hot_pixels(counts, span_s, self.params.hot)
        line = measure_line_width(without_hot_pixels(image, hot), self.params.line)
        return AimFrame(
            t_end_us=self.t_end_us or 0,
            window_us=self.window_us,
            image=image,
            rate_hz=n / span_s if span_s > 0 else 0.0,
            rate_span_s=span_s,
            hot=hot,
            line=line,
            n_events=self.n_events,
            n_outside=self.n_outside,
        )

    def _advance(self, bin_index: int) -> None:
        """Close the open bin if ``bin_index`` is later, and drop the bins older than the rate window."""
        if self._open_bin is None:
            self._open_bin = bin_index
        if bin_index <= self._open_bin:
            return
        counts = None
        if self._open:
            counts = np.bincount(np.concatenate(self._open), minlength=self._n_pixels)
            self._total += counts
        self._closed.append((self._open_bin, counts, self._open_n))
        self._open, self._open_n, self._open_bin = [], 0, bin_index
        while self._closed and self._closed[0][0] <= bin_index - self.n_bins:
            _, old, _ = self._closed.popleft()
            if old is not None:
                self._total -= old
