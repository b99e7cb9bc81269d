"""The flag's root, rest direction and length from a short recording of it moving.

:func:`find_geometry` reads them from the events themselves, in the tracker's frame (pixels, or the
plane's units through a calibration mapping; angles in degrees from +x towards +y):

1. Sensor defects out: hot pixels and events no neighbouring pixel supports (shot noise).
2. The flag's region: the largest connected patch of activity. Its axis of mirror symmetry (the
   flag flaps to both sides of its rest direction) is the rest axis; the end that moves least is
   the root's.
3. The motion field (:mod:`.geometry_field`): the line's lateral position per slice of the axis as
   a combination of its positions at three stations. The slices' time-mean positions refine the
   axis (a straight line through the root at rest).
4. The root: the envelope's apex. Near the pole the flag moves less than a pixel, so the events
   start a little downstream of the root. The amplitude there is read from the event count per
   unit length, which grows in proportion to the amplitude above the sensor's threshold (fitted
   where the amplitude is well measured), and extrapolated to zero (``|Z|^2 = s^2 (b0 + b1 s)``).
5. The length: in each short window the line's farthest point is its tip; the arc length from
   the root to it follows the model's curve; the upper quartile of the windows' lengths is L.
6. What no flag does is refused (:class:`NoFlagError`): a far end moving under 4 pixels, a length
   that changes from window to window, a root off the sensor (one extrapolated a pixel or two off
   it, as a pole at the sensor's edge gives, is put on its edge, and said).

Everything here is pure numpy/scipy: events in, a :class:`FlagGeometry` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from flagtrack.daemon.core.geometry_field import FieldFit, References, fit_field, hot_pixels, references, supported
from flagtrack.daemon.core.geometry_root import length_estimates, root_along_axis, root_onto_sensor
from flagtrack.daemon.core.mapping import PointMapping, on_sensor

_MAX_LENGTH_OVER_DIAGONAL = 1.2
"""A flag seen whole is at most the sensor's diagonal long (20 % more: a calibration's pixel size varies)."""
_MIN_TIP_MOTION_PX = 4.0
"""Least peak-to-peak motion of the far end for a flag (pixels): under it, nothing can be tracked."""
_MAX_LENGTH_SPREAD = 0.06
"""Largest spread of the windows' lengths (half their interquartile range) over L for a flag (the
simulated grid's flags, 72 recordings: at most 0.8 %)."""


class NoFlagError(ValueError):
    """The events show no flag (empty, noise only, nothing that flaps, or what moves cannot be a flag);
    the message says why."""


@dataclass(frozen=True)
class GeometryParams:
    """Tuning of :func:`find_geometry` (the defaults are the measured ones of docs/first-day.md).

    Attributes:
        hot_ratio: a hot pixel fires more than this many times its neighbours' median count.
        hot_min_count: and at least this many events.
        support_us: time slice of the neighbour-support test, µs.
        min_events: fewest supported events in the flag's region for a flag.
        min_extent_px: smallest extent of a flag along its axis, pixels.
        onset_px: amplitude (pixels) at which a pixel starts firing, used when it cannot be fitted.
        slices: slices of the flag's extent for the motion field.
        max_events: events beyond this many (evenly thinned in time order) are not used.
    """

    hot_ratio: float = 4.0
    hot_min_count: int = 10
    support_us: int = 1000
    min_events: int = 2000
    min_extent_px: float = 20.0
    onset_px: float = 0.19
    slices: int = 100
    max_events: int = 4_000_000


@dataclass(frozen=True)
class FlagGeometry:
    """What :func:`find_geometry` found, in the events' (or the mapping's) units.

    Attributes:
        root: (x, y) of the root.
        direction_deg: rest direction, degrees from +x towards +y (the tracker's convention), in [-180, 180).
        length: flag length L.
        root_gap: distance from the root to where the flag first moves enough to fire events (the
            part of the root's position that is extrapolated, not seen).
        length_spread: half the interquartile range of the windows' lengths (a spread, not an error).
        direction_se_deg: standard error of the rest direction from the axis fit.
        amplitude: peak-to-peak lateral motion of the tip.
        frequency_hz: main frequency of the motion (a recording where none repeats is refused).
        periods: flapping periods in the recording (duration x frequency).
        events_used: events of the flag after the defects were removed.
        hot_pixels: (x, y) pixels found hot and ignored.
        at_edge: the flag's envelope reaches the sensor's edge (its length may be cut).
        px_size: size of a pixel near the flag, in these units (1 without a mapping).
        root_pulled: how far downstream the root was moved, onto the sensor, from where the
            extrapolation put it just off (0: not moved).
    """

    root: tuple[float, float]
    direction_deg: float
    length: float
    root_gap: float
    length_spread: float
    direction_se_deg: float
    amplitude: float
    frequency_hz: float
    periods: float
    events_used: int
    hot_pixels: tuple[tuple[int, int], ...]
    at_edge: bool
    px_size: float
    root_pulled: float = 0.0

    def warnings(self) -> list[str]:
        """What is unsure, as sentences (empty when nothing is)."""
        out = []
        if self.root_gap > 0.02 * self.length:
            out.append(
                f"the first {100 * self.root_gap / self.length:.0f} % of the flag barely moves: the root is "
                "extrapolated along the axis (record a larger motion for a surer root)"
            )
        if self.root_pulled > 0:
            out.append(
                f"the root was extrapolated {self.root_pulled / self.px_size:.1f} pixels off the sensor and is put "
                "at its edge: check that the pole is there"
            )
        if self.at_edge:
            out.append("the flag's motion reaches the sensor's edge: the length may be cut short")
        if self.periods < 2:
            out.append(f"only {self.periods:.1f} periods of motion: record longer for surer figures")
        if self.length_spread > 0.03 * self.length:
            out.append(f"the windows' lengths spread by {100 * self.length_spread / self.length:.0f} % of L")
        return out


def find_geometry(
    events: np.ndarray,
    size: tuple[int, int],
    mapping: PointMapping | None = None,
    params: GeometryParams = GeometryParams(),
) -> FlagGeometry:
    """Root, rest direction and length of the flag flapping (or tapped) in ``events``.

    Args:
        events: time-ordered EVENT_DTYPE array.
        size: (width, height) of the sensor, pixels (0: unknown, from the events).
        mapping: pixel -> plane mapping of a calibration (None: pixels).
        params: tuning.

    Raises:
        NoFlagError: no flag in the events (the message says what was seen).
    """
    if len(events) > params.max_events:
        events = events[np.linspace(0, len(events) - 1, params.max_events).astype(np.int64)]
    if len(events) < params.min_events:
        raise NoFlagError(f"{len(events)} events: too few for a flag (at least {params.min_events})")
    width = max(int(size[0]), int(events["x"].max()) + 1)
    height = max(int(size[1]), int(events["y"].max()) + 1)
    clean, support, hot, noise_hz = _clean(events, (width, height), params)
    if support.sum() < params.min_events:
        raise NoFlagError(f"{int(support.sum())} events after removing noise and hot pixels: no flag")
    every = _Events.of(events[clean], mapping)
    scale = every.scale
    seen = every.where(support[clean])
    seen = seen.where(_flag_region(seen.x, seen.y, scale, params))
    sample = seen.where(slice(None, None, max(1, len(seen.x) // 300_000)))
    end_us = _whole_periods(seen.t_us, _frequency_hz(_motion(_Frame.principal(seen.x, seen.y), sample, params)[1]))
    seen, every, sample = (e.where(e.t_us < end_us) for e in (seen, every, sample))
    frame = _Frame.symmetric(seen.x, seen.y, scale)
    if _moves_more_at_start(_motion(frame, sample, params)[0]):
        frame = frame.flipped()
    frame, direction_se = frame.refined(_motion(frame, sample, params)[0])
    fit, refs = _motion(frame, seen, params)
    frequency = _frequency_hz(refs)
    duration_s = (float(events["t"][-1]) - float(events["t"][0])) * 1e-6
    if frequency is None:  # what moves does not move back and forth: no evidence of a flag
        raise NoFlagError(
            f"nothing flaps: no motion repeats within the {duration_s:.2g} s recording "
            "(record the flag flapping, or tapped by hand, for at least a period)"
        )
    noise = noise_hz * (end_us - every.t_us[0]) * 1e-6 / scale**2  # noise events per unit area
    u_root, u_first = root_along_axis(*frame.uv(every.x, every.y), fit, scale, params.onset_px * scale, noise)
    # a pole at the sensor's edge: the extrapolated root may land just off it (by the gap, a pixel or two)
    on_it = (lambda u: on_sensor(*_axis_point(frame, fit, u), *size, mapping)) if min(size) > 0 else None
    u_seen = root_onto_sensor(u_root, max(u_first - u_root, 0.0) + 2.0 * scale, on_it)
    pulled, u_root = u_seen - u_root, u_seen
    u, v = frame.uv(seen.x, seen.y)
    lengths = length_estimates(u, v, seen.t_us, fit, refs, u_root)
    if len(lengths) == 0:
        raise NoFlagError("no window shows the flag's tip: no flag")
    q1, q3 = np.percentile(lengths, [25, 75])
    length_px = q3 / scale
    if length_px > _MAX_LENGTH_OVER_DIAGONAL * math.hypot(width, height):  # root and tip cannot both be in view
        raise NoFlagError(
            f"the moving line would be {length_px:.0f} pixels long, longer than the {width} x {height} "
            "sensor's diagonal: not one flag"
        )
    root = _axis_point(frame, fit, u_root)
    found = FlagGeometry(
        root=(float(root[0]), float(root[1])),
        direction_deg=frame.direction_deg,
        length=float(q3),
        root_gap=float(max(u_first - u_root, 0.0)),
        length_spread=float((q3 - q1) / 2),
        direction_se_deg=direction_se,
        amplitude=_tip_amplitude(fit),
        frequency_hz=frequency,
        periods=float(duration_s * frequency),
        events_used=len(seen.x),
        hot_pixels=tuple((int(px % width), int(px // width)) for px in np.flatnonzero(hot)),
        at_edge=min(size) > 0 and _at_edge(seen, frame, (width, height), u_root, float(q3)),
        px_size=scale,
        root_pulled=float(pulled),
    )
    _refuse_what_no_flag_does(found, size, mapping)
    return found


def _refuse_what_no_flag_does(found: FlagGeometry, size: tuple[int, int], mapping: PointMapping | None) -> None:
    """NoFlagError when what moves cannot be a flag: a far end moving under 4 pixels peak to peak (2
    sqrt(2) times its RMS over the recording's whole periods: a tap followed by a long rest counts low),
    a length that changes from window to window (a flag's spreads by under 0.8 % of L on the
    simulated grid of docs/first-day.md; not judged when the motion reaches the sensor's edge), or a
    root off the sensor (where its size is known: the tracker refuses such a root)."""
    if found.amplitude < _MIN_TIP_MOTION_PX * found.px_size:
        raise NoFlagError(
            f"the far end moves {found.amplitude / found.px_size:.1f} pixels peak to peak, under "
            f"{_MIN_TIP_MOTION_PX:g}: nothing moves enough to be tracked (flap or tap it harder, or bring the "
            "camera closer)"
        )
    spread = found.length_spread / found.length
    if spread > _MAX_LENGTH_SPREAD and not found.at_edge:
        raise NoFlagError(
            f"the moving line's length changes from window to window by {100 * spread:.0f} % of itself "
            "(a flag's: under 0.8 %): not a flag"
        )
    width, height = size
    x, y = found.root
    if min(size) > 0 and not on_sensor(x, y, width, height, mapping):
        plane = " (its outline mapped through the calibration)" if mapping is not None else ""
        raise NoFlagError(
            f"what moves would be rooted at ({x:.4g}, {y:.4g}), off the {width} x {height} sensor{plane}: "
            "a flag's pole is in view"
        )


def _axis_point(frame: _Frame, fit: FieldFit, u: float) -> tuple[float, float]:
    """The point at ``u`` along the axis, on the line's time-mean lateral position there."""
    x, y = frame.point(u, float(np.interp(u, fit.centres, _filled(fit.mean, fit.centres))))
    return float(x), float(y)


@dataclass(frozen=True)
class _Events:
    """Events in the tracker's units: x, y, t (µs, float), polarity (ON), their pixels, pixel size."""

    x: np.ndarray
    y: np.ndarray
    t_us: np.ndarray
    on: np.ndarray
    x_px: np.ndarray
    y_px: np.ndarray
    scale: float

    @staticmethod
    def of(events: np.ndarray, mapping: PointMapping | None) -> _Events:
        x, y, scale = _plane(events, mapping)
        return _Events(x, y, events["t"].astype(np.float64), events["p"] > 0, events["x"], events["y"], scale)

    def where(self, keep: np.ndarray | slice) -> _Events:
        return _Events(
            self.x[keep], self.y[keep], self.t_us[keep], self.on[keep], self.x_px[keep], self.y_px[keep], self.scale
        )


def _clean(
    events: np.ndarray, size: tuple[int, int], params: GeometryParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Events off hot pixels, those also supported by a neighbour (bool, per event), the hot
    pixels (bool over the sensor's flat pixel index) and the noise rate per pixel (Hz)."""
    width, height = size
    x, y = events["x"].astype(np.int64), events["y"].astype(np.int64)
    counts = np.bincount(y * width + x, minlength=width * height).reshape(height, width)
    hot = hot_pixels(counts, params.hot_ratio, params.hot_min_count).reshape(-1)
    duration_s = max((int(events["t"][-1]) - int(events["t"][0])) * 1e-6, 1e-3)
    quiet = counts <= max(10.0, 5.0 * float(np.median(counts)))  # pixels the flag does not cross
    rate_hz = float(counts[quiet].mean()) / duration_s if quiet.any() else 0.0
    need = 1
    while need < 3 and math.comb(8, need) * (rate_hz * 3 * params.support_us * 1e-6) ** need > 0.01:
        need += 1
    clean = ~hot[y * width + x]
    support = clean.copy()
    support[clean] = supported(x[clean], y[clean], events["t"][clean], size, params.support_us, need)
    return clean, support, hot, rate_hz


def _plane(events: np.ndarray, mapping: PointMapping | None) -> tuple[np.ndarray, np.ndarray, float]:
    """Event coordinates in the tracker's units and the size of a pixel there (median near the events)."""
    x_px, y_px = events["x"].astype(np.float64), events["y"].astype(np.float64)
    if mapping is None:
        return x_px, y_px, 1.0
    x, y = mapping.map(x_px, y_px)
    sample = slice(None, None, max(1, len(x_px) // 20_000))
    xs, ys = x_px[sample], y_px[sample]
    ax, ay = mapping.map(xs + 0.5, ys)
    bx, by = mapping.map(xs - 0.5, ys)
    cx, cy = mapping.map(xs, ys + 0.5)
    dx, dy = mapping.map(xs, ys - 0.5)
    area = np.abs((ax - bx) * (cy - dy) - (ay - by) * (cx - dx))
    return np.asarray(x), np.asarray(y), float(np.sqrt(np.median(area)))


def _flag_region(x: np.ndarray, y: np.ndarray, scale: float, params: GeometryParams) -> np.ndarray:
    """Events of the largest connected patch of activity (bool); NoFlagError if it is no flag."""
    cell = 2.0 * scale
    ix = ((x - x.min()) / cell).astype(np.int64)
    iy = ((y - y.min()) / cell).astype(np.int64)
    grid = np.zeros((int(iy.max()) + 1, int(ix.max()) + 1))
    np.add.at(grid, (iy, ix), 1.0)
    smooth = ndimage.gaussian_filter(grid, 1.5)
    level = 0.02 * float(np.percentile(smooth[smooth > 0], 99.5))
    labels, n = ndimage.label(smooth > level, structure=np.ones((3, 3)))
    if n == 0:
        raise NoFlagError("no patch of activity: no flag")
    sums = ndimage.sum(grid, labels, index=np.arange(1, n + 1))
    region = labels[iy, ix] == 1 + int(np.argmax(sums))
    if region.sum() < params.min_events:
        raise NoFlagError(f"the busiest patch has {int(region.sum())} events: no flag")
    xs, ys = x[region], y[region]
    extent = float(np.hypot(*np.ptp(np.column_stack([xs, ys]), axis=0)))
    if extent < params.min_extent_px * scale:
        raise NoFlagError(f"the busiest patch is {extent / scale:.0f} pixels across: no flag")
    return region


def _filled(values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``values`` with NaNs interpolated from their neighbours (zeros if all are NaN)."""
    good = np.isfinite(values)
    if good.sum() < 2:
        return np.zeros_like(values)
    return np.interp(at, at[good], values[good])


@dataclass(frozen=True)
class _Frame:
    """The flag's frame: origin, unit axis (root -> tip) and the normal (axis turned +90 degrees)."""

    origin: np.ndarray
    axis: np.ndarray

    @property
    def normal(self) -> np.ndarray:
        return np.array([-self.axis[1], self.axis[0]])

    @property
    def direction_deg(self) -> float:
        """In [-180, 180): a flag pointing along +x is near 0, either side."""
        return (math.degrees(math.atan2(self.axis[1], self.axis[0])) + 180.0) % 360.0 - 180.0

    def uv(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dx, dy = x - self.origin[0], y - self.origin[1]
        return dx * self.axis[0] + dy * self.axis[1], -dx * self.axis[1] + dy * self.axis[0]

    def point(self, u: float, v: float) -> np.ndarray:
        return self.origin + u * self.axis + v * self.normal

    def flipped(self) -> _Frame:
        return _Frame(self.origin, -self.axis)

    @staticmethod
    def principal(x: np.ndarray, y: np.ndarray) -> _Frame:
        """The activity's major principal axis through its centroid (a first guess)."""
        origin = np.array([x.mean(), y.mean()])
        _, vectors = np.linalg.eigh(np.cov(np.stack([x - origin[0], y - origin[1]])))
        return _Frame(origin, vectors[:, 1])

    @staticmethod
    def symmetric(x: np.ndarray, y: np.ndarray, scale: float) -> _Frame:
        """The axis the activity is most mirror-symmetric about (every 3 degrees, then every 0.5);
        ``x``, ``y`` cover whole periods of the motion (over part of one, a flag's is not symmetric)."""
        cell = 2.0 * scale
        ix, iy = np.floor((x - x.min()) / cell).astype(np.int64), np.floor((y - y.min()) / cell).astype(np.int64)
        counts = np.bincount(iy * (int(ix.max()) + 1) + ix)
        cells = np.flatnonzero(counts >= max(1.0, 0.05 * float(np.percentile(counts[counts > 0], 99))))
        cx = x.min() + (cells % (int(ix.max()) + 1) + 0.5) * cell
        cy = y.min() + (cells // (int(ix.max()) + 1) + 0.5) * cell
        weight = counts[cells].astype(np.float64)
        origin = np.array([np.average(cx, weights=weight), np.average(cy, weights=weight)])

        def frame(angle_deg: float) -> _Frame:
            return _Frame(origin, np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))]))

        def score(angle_deg: float) -> float:
            return _mirror_symmetry(frame(angle_deg).uv(cx, cy), weight, 3.0 * cell)  # bins well over the cells

        best = max(np.arange(0.0, 180.0, 3.0), key=score)
        return frame(max(np.arange(best - 3.0, best + 3.01, 0.5), key=score))

    def refined(self, fit: FieldFit) -> tuple[_Frame, float]:
        """The frame turned and shifted onto the line through the slices' mean positions, and the
        standard error of its direction, degrees."""
        good = np.isfinite(fit.mean) & (fit.count >= 20)
        if good.sum() < 3:
            return self, 90.0
        weight = fit.count[good] / np.maximum(fit.scale[good], 1e-9) ** 2
        (slope, offset), cov = np.polyfit(fit.centres[good], fit.mean[good], 1, w=np.sqrt(weight), cov="unscaled")
        resid = fit.mean[good] - (slope * fit.centres[good] + offset)
        dof = max(int(good.sum()) - 2, 1)
        sigma2 = float(np.sum(weight * resid**2)) / dof
        se_deg = math.degrees(math.sqrt(max(cov[0, 0] * sigma2, 0.0)))
        turn = math.atan(slope)
        c, s = math.cos(turn), math.sin(turn)
        axis = np.array([c * self.axis[0] - s * self.axis[1], s * self.axis[0] + c * self.axis[1]])
        return _Frame(self.origin + offset * self.normal, axis), se_deg


def _mirror_symmetry(uv: tuple[np.ndarray, np.ndarray], weight: np.ndarray, cell: float) -> float:
    """Correlation of the activity with its mirror image across the line v = const (best shift)."""
    u, v = uv
    reach = float(np.abs(v).max()) + cell
    bins = [np.arange(u.min(), u.max() + cell, cell), np.arange(-reach, reach + cell, cell)]
    hist = np.histogram2d(u, v, bins, weights=weight)[0]
    mirror = hist[:, ::-1]
    best = -1.0
    for shift in range(-10, 11):
        moved = np.roll(mirror, shift, axis=1)
        best = max(best, float((hist * moved).sum() / math.sqrt((hist**2).sum() * (moved**2).sum())))
    return best


def _motion(frame: _Frame, events: _Events, params: GeometryParams) -> tuple[FieldFit, References]:
    """The motion field of ``events`` in ``frame``."""
    u, v = frame.uv(events.x, events.y)
    t_us = events.t_us
    lo, hi = np.percentile(u, [0.1, 99.9])
    extent = hi - lo
    stations = lo + np.array([0.35, 0.6, 0.85]) * extent
    half_band = 0.03 * extent
    in_band = int(np.sum(np.abs(u - stations[1]) < half_band))
    duration_us = float(t_us.max() - t_us.min()) + 1.0
    window_us = float(np.clip(40.0 * duration_us / max(in_band, 1), 200.0, 5000.0))
    refs = references(u, v, t_us, stations, half_band, window_us)
    if refs is None:
        raise NoFlagError("the activity does not move as a flag does (no steady line along its axis)")
    edges = np.linspace(lo - 0.05 * extent, hi + 0.02 * extent, params.slices + 1)
    return fit_field(u, v, t_us, events.on, refs, edges), refs


def _moves_more_at_start(fit: FieldFit) -> bool:
    """Whether the low-u end of the field moves more than the high-u end (the root is at the tip's end)."""
    rms = fit.rms
    good = np.flatnonzero(np.isfinite(rms))
    if len(good) < 4:
        return False
    n = max(2, len(good) // 6)
    return float(np.median(rms[good[:n]])) > float(np.median(rms[good[-n:]]))


def _tip_amplitude(fit: FieldFit) -> float:
    """Peak-to-peak lateral motion at the far end (2 sqrt(2) RMS, a sine's)."""
    rms = fit.rms
    good = np.flatnonzero(np.isfinite(rms))
    return float(2.0 * math.sqrt(2.0) * np.max(rms[good[-max(2, len(good) // 10) :]])) if len(good) else 0.0


def _frequency_hz(refs: References) -> float | None:
    """The strongest frequency of the first reference signal (None below one period)."""
    signal = refs.values[:, 0]
    step_s = float(refs.t_us[1] - refs.t_us[0]) * 1e-6
    n = len(signal)
    spectrum = np.log(np.abs(np.fft.rfft((signal - signal.mean()) * np.hanning(n), 16 * n)) + 1e-12)
    i = int(np.argmax(spectrum[1:-1])) + 1
    a, b, c = spectrum[i - 1], spectrum[i], spectrum[i + 1]
    offset = 0.5 * (a - c) / (a - 2 * b + c) if a - 2 * b + c < 0 else 0.0
    frequency = (i + offset) / (16 * n * step_s)
    return frequency if frequency * n * step_s >= 1.0 else None


def _whole_periods(t_us: np.ndarray, frequency_hz: float | None) -> float:
    """End of the first whole number of periods (past the end if under one): a flag's motion is
    symmetric about its rest axis over whole periods, not over a part of one."""
    end = float(t_us[-1]) + 1.0
    if not frequency_hz:
        return end
    period_us = 1e6 / frequency_hz
    n = int((end - t_us[0]) // period_us)
    return float(t_us[0]) + n * period_us if n >= 1 else end


def _at_edge(events: _Events, frame: _Frame, size: tuple[int, int], u_root: float, length: float) -> bool:
    """Whether events near the flag's far end touch the sensor's border."""
    far = frame.uv(events.x, events.y)[0] > u_root + 0.8 * length
    x, y = events.x_px[far].astype(np.int64), events.y_px[far].astype(np.int64)
    if len(x) == 0:
        return False
    edge = (x <= 1) | (y <= 1) | (x >= size[0] - 2) | (y >= size[1] - 2)
    return bool(edge.sum() >= 3)
