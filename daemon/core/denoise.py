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

_NEVER = np.int32(-(1 << 31) + 1)  # "never fired", in the int32 map of times relative to a base
_REBASE_US = 1 << 30  # move the base forward when times get this far from it (~18 minutes)


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
def _fired_recently(last: np.ndarray, stride: int, x: int, y: int, t_rel: np.int32, window_us: np.int32) -> bool:
    """Whether a neighbour of pixel (x, y) fired within ``window_us`` before ``t_rel``; records ``t_rel``."""
    row = np.uint64(stride)
    one = np.uint64(1)
    c = (np.uint64(y) + one) * row + np.uint64(x) + one
    up = c - row
    dn = c + row
    recent = max(max(max(last[up - one], last[up]), max(last[up + one], last[c - one])),
                 max(max(last[c + one], last[dn - one]), max(last[dn], last[dn + one])))
    last[c] = t_rel
    return recent >= t_rel - window_us


@njit(cache=True, nogil=True, error_model="numpy")
def scan_chunk(t: np.ndarray, x: np.ndarray, y: np.ndarray, latest: int) -> tuple[bool, int, int, int]:
    """(times never decrease from ``latest`` on, latest time, largest x, largest y) of a chunk."""
    ordered = True
    top, max_x, max_y = latest, 0, 0
    for i in range(len(t)):
        ti = np.int64(t[i])
        ordered &= ti >= top
        top = max(top, ti)
        max_x = max(max_x, np.int64(x[i]))
        max_y = max(max_y, np.int64(y[i]))
    return ordered, top, max_x, max_y


@njit(cache=True, nogil=True, error_model="numpy")
def filter_and_convert(t: np.ndarray, x: np.ndarray, y: np.ndarray, last: np.ndarray, stride: int, base_us: int,
                       window_us: int, out_t: np.ndarray, out_x: np.ndarray, out_y: np.ndarray, start: int) -> int:
    """Filter events through the time map ``last`` and append the kept ones as float coordinates.

    Args:
        t, x, y: the events (may be strided views of an event array), inside the map.
        last: flat ((height + 2) * stride,) int32 time (µs after ``base_us``) of each pixel's last
            event, updated; pixel (x, y) is ``last[(y + 1) * stride + x + 1]`` (a one-pixel border
            that never fires). Times must stay within 2^31 µs of the base.
        stride: width + 2.
        base_us: time origin of the map.
        window_us: the filter window, µs.
        out_t, out_x, out_y: output buffers, written from index ``start``.

    Returns:
        The index after the last written event.
    """
    j = start
    window = np.int32(window_us)
    for i in range(len(t)):
        ti = np.int64(t[i])
        keep = _fired_recently(last, stride, x[i], y[i], np.int32(ti - base_us), window)
        out_t[j] = ti  # written always, kept by advancing j: no branch
        out_x[j] = x[i]
        out_y[j] = y[i]
        j += 1 if keep else 0
    return j


@njit(cache=True, nogil=True, error_model="numpy")
def filter_indices(t: np.ndarray, x: np.ndarray, y: np.ndarray, last: np.ndarray, stride: int, base_us: int,
                   window_us: int, out_index: np.ndarray) -> int:
    """Like :func:`filter_and_convert`, writing the indices of the kept events; returns their number."""
    j = 0
    window = np.int32(window_us)
    for i in range(len(t)):
        out_index[j] = i
        j += 1 if _fired_recently(last, stride, x[i], y[i], np.int32(np.int64(t[i]) - base_us), window) else 0
    return j


class BackgroundActivityFilter:
    """Stateful background-activity filter over a stream of events (chunks in time order).

    Args:
        params: filter settings, or ``None`` to keep every event.
        width, height: sensor size in pixels if known (the map grows to fit larger coordinates).
    """

    def __init__(self, params: DenoiseParams | None, width: int = 0, height: int = 0) -> None:
        self.params = params
        self._width, self._height = (width, height) if params else (0, 0)
        self._last = np.full((self._height + 2) * (self._width + 2), _NEVER, dtype=np.int32)
        self._base_us: int | None = None

    def _fit(self, max_x: int, max_y: int) -> None:
        """Grow the time map so that pixel (max_x, max_y) fits (kept times are preserved)."""
        width, height = max(self._width, max_x + 1), max(self._height, max_y + 1)
        if (width, height) != (self._width, self._height):
            grown = np.full((height + 2, width + 2), _NEVER, dtype=np.int32)
            grown[:self._height + 2, :self._width + 2] = self._last.reshape(self._height + 2, self._width + 2)
            self._last = grown.ravel()
            self._width, self._height = width, height

    def _prepare(self, events: np.ndarray, latest: int) -> tuple[bool, int]:
        """Fit the map and its time base to a chunk; return (in time order, latest time)."""
        ordered, latest, max_x, max_y = scan_chunk(events["t"], events["x"], events["y"], latest)
        if self.params is not None:
            self._fit(max_x, max_y)
            t0, t1 = int(events["t"][0]), latest
            if self._base_us is None:
                self._base_us = t0
            elif max(abs(t1 - self._base_us), abs(t0 - self._base_us)) >= _REBASE_US:
                shift = t0 - self._base_us
                self._last = np.maximum(self._last.astype(np.int64) - shift, _NEVER).astype(np.int32)
                self._base_us = t0
        return ordered, latest

    def filter_into(self, events: np.ndarray, out_t: np.ndarray, out_x: np.ndarray, out_y: np.ndarray,
                    start: int, latest_us: int = -(1 << 62)) -> tuple[int, bool, int]:
        """Append t, x, y of the kept events of ``events`` (EVENT_DTYPE) to the buffers from ``start``.

        Args:
            latest_us: latest event time seen before this chunk (for the order check).

        Returns:
            (index after the last written event, whether the chunk continues the time order, latest
            event time).
        """
        if len(events) == 0:
            return start, True, latest_us
        span = int(events["t"][-1]) - int(events["t"][0])
        if self.params is not None and len(events) > 1 and abs(span) >= _REBASE_US:
            half = len(events) // 2  # a chunk across a long gap: keep the times within int32 of the base
            end, ordered, latest = self.filter_into(events[:half], out_t, out_x, out_y, start, latest_us)
            end, ordered_2, latest = self.filter_into(events[half:], out_t, out_x, out_y, end, latest)
            return end, ordered and ordered_2, latest
        ordered, latest = self._prepare(events, latest_us)
        t, x, y = events["t"], events["x"], events["y"]
        if self.params is None:
            return _copy_into(t, x, y, out_t, out_x, out_y, start), ordered, latest
        end = filter_and_convert(t, x, y, self._last, self._width + 2, self._base_us, self.params.window_us,
                                 out_t, out_x, out_y, start)
        return end, ordered, latest

    def keep_mask(self, events: np.ndarray) -> np.ndarray:
        """Boolean (n,) mask of the events the filter keeps (the filter state advances)."""
        mask = np.ones(len(events), dtype=bool)
        if self.params is None or len(events) == 0:
            return mask
        if len(events) > 1 and abs(int(events["t"][-1]) - int(events["t"][0])) >= _REBASE_US:
            half = len(events) // 2  # see filter_into
            return np.concatenate([self.keep_mask(events[:half]), self.keep_mask(events[half:])])
        self._prepare(events, -(1 << 62))
        index = np.empty(len(events), dtype=np.int64)
        end = filter_indices(events["t"], events["x"], events["y"], self._last, self._width + 2, self._base_us,
                             self.params.window_us, index)
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
