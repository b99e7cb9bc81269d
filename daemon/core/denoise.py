"""Background-activity filter: keep an event only if neighbouring pixels fired shortly before.

The filter that event-camera libraries use against background activity (jAER's
``BackgroundActivityFilter``, tonic's ``denoise``): each pixel remembers the time of its last event;
an event passes when one of the 8 pixels around it (its 3x3 neighbourhood *without its own pixel*)
fired within the last ``window_us``. A moving line lights its neighbours within microseconds,
so its events pass; uniform background events rarely have a neighbour that fired within the window,
and a hot pixel firing on its own never does (its own past events are not counted).

**Adaptive support** (``max_neighbours > min_neighbours``): with dense background noise (shot noise,
v2e-style leak events) one neighbour within the window is often there by chance (about
``8 r w`` for a noise rate ``r`` per pixel), while a lit line lights several neighbours at once.
The filter estimates ``r`` over blocks of ``block_us`` from the events none of whose neighbours
fired within the window (isolated: noise, not line), and for the next block asks for the fewest
neighbours ``k`` in ``[min_neighbours, max_neighbours]`` such that a noise event passes with
probability ``C(8, k) (r w)^k <= noise_pass``. Sparse clean recordings keep ``k = 1``.

The filter runs on sensor pixels, before any calibration mapping, and its state (the time map, the
block statistics) advances event by event, so the result does not depend on how a stream is cut.
"""

from __future__ import annotations

import math

import numpy as np

from flagtrack.daemon.core.denoise_params import DenoiseParams
from flagtrack.daemon.core.events import MAX_SENSOR_PX, beyond_any_sensor
from flagtrack.daemon.core.jit import njit

__all__ = ["BackgroundActivityFilter", "DenoiseParams"]

GROW_PASS = 0.25
"""A window grows beyond ``window_us`` only while a noise event passes it with at most this share of
``noise_pass`` (so where the fixed window already lets noise through, it stays fixed)."""
_NEVER = np.int32(-(1 << 31) + 1)  # "never fired", in the int32 map of times relative to a base
_REBASE_US = 1 << 30  # move the base forward when times get this far from it (~18 minutes)


class BeyondAnySensorError(ValueError):
    """An event at a pixel no event sensor has (not an event recording, or a corrupt one)."""


# state vector of the adaptive rule (int64): block index, isolated events in it, current k,
# largest x and y seen so far (the sensor area, grown event by event so chunking cannot matter),
# current support window (µs)
_BLOCK, _ISOLATED, _K, _MAX_X, _MAX_Y, _W = range(6)


def initial_state(min_neighbours: int, window_us: int = 0) -> np.ndarray:
    """A fresh (6,) int64 state of the adaptive rule."""
    return np.array([np.iinfo(np.int64).min, 0, min_neighbours, 0, 0, window_us], dtype=np.int64)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _support(last: np.ndarray, stride: int, x: int, y: int, t_rel: np.int32, window_us: np.int32) -> int:
    """How many of the 8 neighbours of pixel (x, y) fired within ``window_us`` before ``t_rel``;
    records ``t_rel`` as the pixel's last event."""
    row = np.uint64(stride)
    one = np.uint64(1)
    c = (np.uint64(y) + one) * row + np.uint64(x) + one
    up = c - row
    dn = c + row
    since = t_rel - window_us
    count = (
        (last[up - one] >= since)
        + (last[up] >= since)
        + (last[up + one] >= since)
        + (last[c - one] >= since)
        + (last[c + one] >= since)
        + (last[dn - one] >= since)
        + (last[dn] >= since)
        + (last[dn + one] >= since)
    )
    last[c] = t_rel
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def _next_rule(
    isolated: int,
    area_px: float,
    block_us: int,
    window_us: int,
    used_us: int,
    max_window_us: int,
    k_min: int,
    k_max: int,
    noise_pass: float,
    comb: np.ndarray,
) -> tuple[int, int]:
    """(neighbours, window µs) for the next block, from the isolated events of the last one (seen
    with a window of ``used_us``): the longest window up to ``max_window_us`` for which a noise event
    passes ``k_min`` neighbours with at most ``GROW_PASS * noise_pass`` chance, else ``window_us`` and the fewest
    neighbours for which it does."""
    p = isolated / (area_px * block_us) * used_us  # chance a given neighbour fired in the window
    p = p * math.exp(min(8.0 * p, 8.0))  # isolated events are the noise with no neighbour
    if max_window_us > window_us and k_min == 1:
        longest = GROW_PASS * noise_pass / (comb[1] * p) * used_us if p > 0.0 else math.inf
        if longest > window_us:
            return k_min, int(min(longest, float(max_window_us)))
    if used_us != window_us:
        p = p / used_us * window_us
    p = min(p, 1.0)
    k = k_min
    while k < k_max and comb[k] * p**k > noise_pass:
        k += 1
    return k, window_us


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _required(
    state: np.ndarray,
    t: np.int64,
    x: np.int64,
    y: np.int64,
    block_us: int,
    window_us: int,
    max_window_us: int,
    k_min: int,
    k_max: int,
    noise_pass: float,
    comb: np.ndarray,
) -> int:
    """Neighbours an event at (t, x, y) needs (its window is then ``state[_W]``); advances the block
    statistics to its block."""
    if k_max <= k_min and max_window_us <= window_us:
        return k_min
    state[_MAX_X] = max(state[_MAX_X], x)
    state[_MAX_Y] = max(state[_MAX_Y], y)
    block = t // block_us
    if block != state[_BLOCK]:
        area_px = float((state[_MAX_X] + 1) * (state[_MAX_Y] + 1))
        if block == state[_BLOCK] + 1:
            state[_K], state[_W] = _next_rule(
                state[_ISOLATED], area_px, block_us, window_us, state[_W], max_window_us, k_min, k_max, noise_pass, comb
            )
        else:  # first block, or blocks without events: no evidence of noise
            state[_K], state[_W] = k_min, window_us
        state[_BLOCK] = block
        state[_ISOLATED] = 0
    return state[_K]


@njit(cache=True, nogil=True, error_model="numpy")
def _filter_mask(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    last: np.ndarray,
    stride: int,
    base_us: int,
    window_us: int,
    max_window_us: int,
    state: np.ndarray,
    block_us: int,
    k_min: int,
    k_max: int,
    noise_pass: float,
    comb: np.ndarray,
    keep: np.ndarray,
) -> None:
    """Write in ``keep`` (n,) whether each event passes; the map and state advance."""
    adaptive = k_max > k_min or max_window_us > window_us
    for i in range(len(t)):
        ti = np.int64(t[i])
        need = _required(
            state,
            ti,
            np.int64(x[i]),
            np.int64(y[i]),
            block_us,
            window_us,
            max_window_us,
            k_min,
            k_max,
            noise_pass,
            comb,
        )
        window = np.int32(state[_W] if adaptive else window_us)
        n = _support(last, stride, x[i], y[i], np.int32(ti - base_us), window)
        state[_ISOLATED] += 1 if n == 0 else 0
        keep[i] = n >= need


# The kernels below compare and take max() of np.int64 and int (``latest = max(latest, ti)``). numba
# compiles both as int64 and returns int and bool to Python, as their signatures say; to mypy, with
# numpy's stubs, np.int64 and np.bool are not int and bool: hence ``type: ignore[assignment]`` there.
@njit(cache=True, nogil=True, error_model="numpy")
def _filter_into(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    i: int,
    last: np.ndarray,
    width: int,
    height: int,
    base_us: int,
    window_us: int,
    max_window_us: int,
    state: np.ndarray,
    block_us: int,
    k_min: int,
    k_max: int,
    noise_pass: float,
    comb: np.ndarray,
    out_t: np.ndarray,
    out_x: np.ndarray,
    out_y: np.ndarray,
    j: int,
    latest: int,
) -> tuple[int, int, int, bool]:
    """:func:`_filter_mask` and the copy of the kept events in one pass (the hot path), from event ``i``:
    append the kept ones from ``j``, and follow the time order from ``latest`` (the latest time before).

    Stops at the first event outside the ``width`` x ``height`` map or too far in time from ``base_us``
    for the int32 map, which the caller makes room for before calling again from there.

    Returns:
        (index of the event it stopped at, or ``len(t)``; index after the last kept event; latest time;
        whether the times never decreased). The adaptive state lives in locals during the loop.
    """
    window = np.int32(window_us)
    stride = width + 2
    ordered = True
    n = len(t)
    if k_max <= k_min and max_window_us <= window_us:  # the classic filter: no block statistics
        while i < n:
            ti, xi, yi = np.int64(t[i]), np.int64(x[i]), np.int64(y[i])
            if xi >= width or yi >= height or abs(ti - base_us) >= _REBASE_US:
                break
            ordered &= ti >= latest  # type: ignore[assignment]
            latest = max(latest, ti)  # type: ignore[assignment]
            count = _support(last, stride, x[i], y[i], np.int32(ti - base_us), window)
            out_t[j] = ti  # written always, kept by advancing j: no branch
            out_x[j] = x[i]
            out_y[j] = y[i]
            j += 1 if count >= k_min else 0
            i += 1
        return i, j, latest, ordered
    block_now, k, isolated, used = state[_BLOCK], state[_K], state[_ISOLATED], state[_W]
    max_x, max_y = state[_MAX_X], state[_MAX_Y]
    window = np.int32(used)
    block_lo, block_hi = np.int64(1), np.int64(0)  # times of block_now: [lo, hi); empty: divide first
    while i < n:
        ti, xi, yi = np.int64(t[i]), np.int64(x[i]), np.int64(y[i])
        if xi >= width or yi >= height or abs(ti - base_us) >= _REBASE_US:
            break
        ordered &= ti >= latest  # type: ignore[assignment]
        latest = max(latest, ti)  # type: ignore[assignment]
        max_x, max_y = max(max_x, xi), max(max_y, yi)
        if ti < block_lo or ti >= block_hi:  # ti // block_us != block_now, without a division per event
            block = ti // block_us
            block_lo = block * block_us
            block_hi = block_lo + block_us
        else:
            block = block_now
        if block != block_now:
            if block == block_now + 1:
                area_px = float((max_x + 1) * (max_y + 1))
                k, used = _next_rule(
                    isolated, area_px, block_us, window_us, used, max_window_us, k_min, k_max, noise_pass, comb
                )
            else:  # first block, or blocks without events: no evidence of noise
                k, used = k_min, window_us
            block_now, isolated, window = block, 0, np.int32(used)
        count = _support(last, stride, x[i], y[i], np.int32(ti - base_us), window)
        isolated += 1 if count == 0 else 0
        out_t[j] = ti
        out_x[j] = x[i]
        out_y[j] = y[i]
        j += 1 if count >= k else 0
        i += 1
    state[_BLOCK], state[_K], state[_ISOLATED], state[_MAX_X], state[_MAX_Y], state[_W] = (
        block_now, k, isolated, max_x, max_y, used
    )  # fmt: skip
    return i, j, latest, ordered


@njit(cache=True, nogil=True, error_model="numpy")
def scan_chunk(t: np.ndarray, x: np.ndarray, y: np.ndarray, latest: int) -> tuple[bool, int, int, int]:
    """(times never decrease from ``latest`` on, latest time, largest x, largest y) of a chunk."""
    ordered = True
    top, max_x, max_y = latest, 0, 0
    for i in range(len(t)):
        ti = np.int64(t[i])
        ordered &= ti >= top  # type: ignore[assignment]
        top = max(top, ti)  # type: ignore[assignment]
        max_x = max(max_x, np.int64(x[i]))  # type: ignore[assignment]
        max_y = max(max_y, np.int64(y[i]))  # type: ignore[assignment]
    return ordered, top, max_x, max_y


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
        self._state = initial_state(params.min_neighbours if params else 1, params.window_us if params else 0)
        self._comb = params.thresholds() if params else np.ones(9)

    @property
    def required_neighbours(self) -> int:
        """Neighbours the current block asks for (adaptive rule; ``min_neighbours`` when fixed)."""
        return int(self._state[_K])

    def _mask(self, events: np.ndarray) -> np.ndarray:
        """(n,) bool: the events of a prepared chunk that pass (the map and block state advance)."""
        p, base_us = self.params, self._base_us
        if p is None or base_us is None:
            raise RuntimeError("_mask() before _prepare()")
        keep = np.empty(len(events), dtype=np.bool_)
        _filter_mask(
            events["t"],
            events["x"],
            events["y"],
            self._last,
            self._width + 2,
            base_us,
            p.window_us,
            p.longest_window_us,
            self._state,
            p.block_us,
            p.min_neighbours,
            p.max_neighbours,
            p.noise_pass,
            self._comb,
            keep,
        )
        return keep

    def _fit(self, max_x: int, max_y: int) -> None:
        """Grow the time map so that pixel (max_x, max_y) fits (kept times are preserved)."""
        width, height = max(self._width, max_x + 1), max(self._height, max_y + 1)
        if max(width, height) > MAX_SENSOR_PX:  # (a random file as a headerless DAT: a 1 GB map, then 5)
            raise BeyondAnySensorError(beyond_any_sensor(max_x, max_y))
        if (width, height) != (self._width, self._height):
            grown = np.full((height + 2, width + 2), _NEVER, dtype=np.int32)
            grown[: self._height + 2, : self._width + 2] = self._last.reshape(self._height + 2, self._width + 2)
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
                self._rebase(t0)
        return ordered, latest

    def _rebase(self, base_us: int) -> None:
        """Move the time base of the int32 map to ``base_us`` (times older than the map can hold
        become "never"; they are far older than any window)."""
        assert self._base_us is not None, "_rebase() before the first time base"
        shift = base_us - self._base_us
        self._last = np.maximum(self._last.astype(np.int64) - shift, _NEVER).astype(np.int32)
        self._base_us = base_us

    def filter_into(
        self,
        events: np.ndarray,
        out_t: np.ndarray,
        out_x: np.ndarray,
        out_y: np.ndarray,
        start: int,
        latest_us: int = -(1 << 62),
    ) -> tuple[int, bool, int]:
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
        t, x, y = events["t"], events["x"], events["y"]
        if self.params is None:
            end, latest, ordered = _copy_into(t, x, y, out_t, out_x, out_y, start, latest_us)
            return end, ordered, latest
        p = self.params
        if self._base_us is None:
            self._base_us = int(t[0])
        i, end, latest, ordered = 0, start, latest_us, True
        while True:  # the kernel stops where the map needs to grow or its time base to move
            i, end, latest, ordered_part = _filter_into(
                t,
                x,
                y,
                i,
                self._last,
                self._width,
                self._height,
                self._base_us,
                p.window_us,
                p.longest_window_us,
                self._state,
                p.block_us,
                p.min_neighbours,
                p.max_neighbours,
                p.noise_pass,
                self._comb,
                out_t,
                out_x,
                out_y,
                end,
                latest,
            )
            ordered &= ordered_part
            if i == len(t):
                return end, ordered, latest
            if x[i] >= self._width or y[i] >= self._height:
                self._fit(int(x[i:].max()), int(y[i:].max()))
            if abs(int(t[i]) - self._base_us) >= _REBASE_US:
                self._rebase(int(t[i]))

    def keep_mask(self, events: np.ndarray) -> np.ndarray:
        """Boolean (n,) mask of the events the filter keeps (the filter state advances)."""
        mask = np.ones(len(events), dtype=bool)
        if self.params is None or len(events) == 0:
            return mask
        if len(events) > 1 and abs(int(events["t"][-1]) - int(events["t"][0])) >= _REBASE_US:
            half = len(events) // 2  # see filter_into
            return np.concatenate([self.keep_mask(events[:half]), self.keep_mask(events[half:])])
        self._prepare(events, -(1 << 62))
        return self._mask(events)


@njit(cache=True, nogil=True, error_model="numpy")
def _copy_into(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    out_t: np.ndarray,
    out_x: np.ndarray,
    out_y: np.ndarray,
    start: int,
    latest: int,
) -> tuple[int, int, bool]:
    """Append every event (no filtering); return (index after the last, latest time, whether the
    times never decreased from ``latest`` on)."""
    ordered = True
    for i in range(len(t)):
        ti = np.int64(t[i])
        ordered &= ti >= latest  # type: ignore[assignment]
        latest = max(latest, ti)  # type: ignore[assignment]
        out_t[start + i] = ti
        out_x[start + i] = x[i]
        out_y[start + i] = y[i]
    return start + len(t), latest, ordered
