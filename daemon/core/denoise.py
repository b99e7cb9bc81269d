"""Background-activity filter: keep an event only if a neighbouring pixel fired shortly before.

The filter that event-camera libraries use against background activity (jAER's
``BackgroundActivityFilter``, tonic's ``denoise``): each pixel remembers the time of its last event;
an event passes when one of the 8 pixels around it (its 3x3 neighbourhood *without its own pixel*)
fired within the last ``window_us``. A moving line lights its neighbours within microseconds,
so its events pass; uniform background events rarely have a neighbour that fired within the window,
and a hot pixel firing on its own never does (its own past events are not counted). The filter runs
on sensor pixels, before any calibration mapping, and its state (the time map) carries across
chunks, so the result does not depend on how a stream is cut.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

_NEVER = np.int64(-(1 << 62))


@dataclass(frozen=True)
class DenoiseParams:
    """Background-activity filter settings.

    Attributes:
        window_us: an event passes if one of its 8 neighbouring pixels fired within this many µs
            before it (the 3x3 neighbourhood; a 5x5 one let more noise through, docs/tracking.md).
    """

    window_us: int = 500

    def __post_init__(self) -> None:
        if self.window_us <= 0:
            raise ValueError(f"window_us must be positive, got {self.window_us}")


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _fired_recently(last: np.ndarray, stride: int, x: int, y: int, t: int, window_us: int) -> bool:
    """Whether a neighbour of pixel (x, y) fired within ``window_us`` before ``t``; records ``t``."""
    row = np.uint64(stride)
    one = np.uint64(1)
    c = (np.uint64(y) + one) * row + np.uint64(x) + one
    up = c - row
    dn = c + row
    recent = max(max(max(last[up - one], last[up]), max(last[up + one], last[c - one])),
                 max(max(last[c + one], last[dn - one]), max(last[dn], last[dn + one])))
    last[c] = t
    return recent >= t - window_us


@njit(cache=True, nogil=True, error_model="numpy")
def filter_and_convert(t: np.ndarray, x: np.ndarray, y: np.ndarray, last: np.ndarray, stride: int, height: int,
                       window_us: int, out_t: np.ndarray, out_x: np.ndarray, out_y: np.ndarray, start: int,
                       first: int) -> tuple[int, int]:
    """Filter events through the time map ``last`` and append the kept ones as float coordinates.

    Args:
        t, x, y: the events (may be strided views of an event array); x < stride - 2.
        last: flat ((height + 2) * stride,) int64 time of each pixel's last event, updated; pixel
            (x, y) is ``last[(y + 1) * stride + x + 1]`` (a one-pixel border that never fires).
        stride, height: width + 2 and height of the map.
        window_us: the filter window, µs.
        out_t, out_x, out_y: output buffers, written from index ``start``.
        first: index of the first event to take.

    Returns:
        (index after the last written event, index of the first event not taken: len(t), or the
        first event outside the map, which must grow before calling again from there).
    """
    j = start
    width = stride - 2
    for i in range(first, len(t)):
        if (x[i] >= width) | (y[i] >= height):
            return j, i
        ti = np.int64(t[i])
        keep = _fired_recently(last, stride, x[i], y[i], ti, window_us)
        out_t[j] = ti  # written always, kept by advancing j: no branch
        out_x[j] = x[i]
        out_y[j] = y[i]
        j += 1 if keep else 0
    return j, len(t)


@njit(cache=True, nogil=True, error_model="numpy")
def filter_indices(t: np.ndarray, x: np.ndarray, y: np.ndarray, last: np.ndarray, stride: int, height: int,
                   window_us: int, out_index: np.ndarray, start: int, first: int) -> tuple[int, int]:
    """Like :func:`filter_and_convert`, writing the indices of the kept events."""
    j = start
    width = stride - 2
    for i in range(first, len(t)):
        if (x[i] >= width) | (y[i] >= height):
            return j, i
        out_index[j] = i
        j += 1 if _fired_recently(last, stride, x[i], y[i], np.int64(t[i]), window_us) else 0
    return j, len(t)


class BackgroundActivityFilter:
    """Stateful background-activity filter over a stream of events (chunks in time order).

    Args:
        params: filter settings, or ``None`` to keep every event.
        width, height: sensor size in pixels if known (the map grows to fit larger coordinates).
    """

    def __init__(self, params: DenoiseParams | None, width: int = 0, height: int = 0) -> None:
        self.params = params
        self._width, self._height = (width, height) if params else (0, 0)
        self._last = np.full((self._height + 2) * (self._width + 2), _NEVER, dtype=np.int64)

    def _fit(self, events: np.ndarray) -> None:
        """Grow the time map so that every event's pixel fits (kept times are preserved)."""
        if len(events) == 0:
            return
        width = max(self._width, int(events["x"].max()) + 1)
        height = max(self._height, int(events["y"].max()) + 1)
        if (width, height) != (self._width, self._height):
            grown = np.full((height + 2, width + 2), _NEVER, dtype=np.int64)
            grown[:self._height + 2, :self._width + 2] = self._last.reshape(self._height + 2, self._width + 2)
            self._last = grown.ravel()
            self._width, self._height = width, height

    def filter_into(self, events: np.ndarray, out_t: np.ndarray, out_x: np.ndarray, out_y: np.ndarray,
                    start: int) -> int:
        """Append t, x, y of the kept events of ``events`` (EVENT_DTYPE) to the buffers from ``start``.

        Returns:
            The index after the last written event.
        """
        if self.params is None:
            return _copy_into(events["t"], events["x"], events["y"], out_t, out_x, out_y, start)
        t, x, y = events["t"], events["x"], events["y"]
        end, stop = filter_and_convert(t, x, y, self._last, self._width + 2, self._height, self.params.window_us,
                                       out_t, out_x, out_y, start, 0)
        while stop < len(events):
            self._fit(events[stop:])
            end, stop = filter_and_convert(t, x, y, self._last, self._width + 2, self._height,
                                           self.params.window_us, out_t, out_x, out_y, end, stop)
        return end

    def keep_mask(self, events: np.ndarray) -> np.ndarray:
        """Boolean (n,) mask of the events the filter keeps (the filter state advances)."""
        mask = np.ones(len(events), dtype=bool)
        if self.params is None or len(events) == 0:
            return mask
        t, x, y = events["t"], events["x"], events["y"]
        index = np.empty(len(events), dtype=np.int64)
        end, stop = filter_indices(t, x, y, self._last, self._width + 2, self._height, self.params.window_us,
                                   index, 0, 0)
        while stop < len(events):
            self._fit(events[stop:])
            end, stop = filter_indices(t, x, y, self._last, self._width + 2, self._height, self.params.window_us,
                                       index, end, stop)
        mask[:] = False
        mask[index[:end]] = True
        return mask

    def apply(self, events: np.ndarray) -> np.ndarray:
        """Return the kept events (a new array; the filter state advances)."""
        return events[self.keep_mask(events)]


@njit(cache=True, nogil=True, error_model="numpy")
def _copy_into(t: np.ndarray, x: np.ndarray, y: np.ndarray, out_t: np.ndarray, out_x: np.ndarray,
               out_y: np.ndarray, start: int) -> int:
    """Append every event (no filtering)."""
    for i in range(len(t)):
        out_t[start + i] = t[i]
        out_x[start + i] = x[i]
        out_y[start + i] = y[i]
    return start + len(t)
