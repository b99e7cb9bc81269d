"""Pseudo-image of a blinking pattern: find the blink period and phase, then add up the switches.

A pattern shown on a screen that is switched on and off makes every lit pixel fire a burst of ON
events at each switch-on and of OFF events at each switch-off. The running sum of ON - OFF counts
over the whole sensor (the "level") is then a square wave of the blink period, whatever the screen
does in between:

- the level is first smoothed by two running means of a sixth and an eighth of the shortest
  period searched (of the given period if known): 6.7 and 5 ms by default, which damp the
  flicker of a real screen's PWM (any component above ~4 / shortest period, e.g. 300 Hz to 0.3 %);
- the period is the lag that best separates the level's autocorrelation at the lag from the one at
  half the lag (+1 and -1 for a square wave), so slow drifts (leak: ON only) do not count;
- the blink is accepted if the level's steps at the switches stand well above its changes over
  the same span elsewhere (a random walk of noise events has no such steps);
- switch-ons and switch-offs are the strongest rises and falls of the level over an eighth of a
  period (one of each per period), timed where the level crosses halfway;
- the image is, per pixel, the net ON - OFF count in a window centred on each switch-on minus the
  one centred on each switch-off (tapered ends), averaged over the switches. Flicker, shot noise
  and leak add about as many ON as OFF events (or the same number to both windows) and cancel;
  the pattern's lit parts add up.

Limit: the pattern must alternate with a dark screen (not with its own negative, whose level does
not move).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from flagtrack.calibration.errors import CalibrationError

log = logging.getLogger(__name__)

_MAX_BINS = 1 << 21


@dataclass(frozen=True)
class BlinkSearch:
    """How to find the blink.

    Attributes:
        min_period_us: shortest blink period looked for, µs (faster flicker is smoothed out).
        max_period_us: longest blink period looked for, µs.
        period_us: known blink period, µs (skips the search; the phase is still detected).
        min_strength: weakest square-wave score accepted (0..1; 1 = a perfect square wave).
        min_step_snr: weakest switch step accepted, in robust standard deviations of the
            level's changes away from the switches.
    """

    min_period_us: int = 40_000
    max_period_us: int = 5_000_000
    period_us: float | None = None
    min_strength: float = 0.3
    min_step_snr: float = 8.0

    def __post_init__(self) -> None:
        if not 0 < self.min_period_us < self.max_period_us:
            raise ValueError("BlinkSearch needs 0 < min_period_us < max_period_us")
        if self.period_us is not None and not self.period_us > 0:
            raise ValueError("BlinkSearch.period_us must be > 0")


class BlinkSummary(TypedDict):
    """:meth:`BlinkTiming.to_attrs`: the blink as the calibration file records it."""

    period_us: float
    n_on: int
    n_off: int
    half_window_us: float
    strength: float
    step_snr: float | None
    first_on_us: float | None


@dataclass(frozen=True)
class BlinkTiming:
    """The blink found in a recording.

    Attributes:
        period_us: blink period, µs.
        on_us: times of the switch-ons whose window lies inside the recording, µs.
        off_us: times of the switch-offs whose window lies inside the recording, µs.
        half_window_us: half the width of the window around each switch, µs.
        strength: square-wave score of the level at the period (0..1).
        step_snr: median switch step over the robust spread of the level's changes elsewhere.
    """

    period_us: float
    on_us: tuple[float, ...]
    off_us: tuple[float, ...]
    half_window_us: float
    strength: float
    step_snr: float = math.inf

    def to_attrs(self) -> BlinkSummary:
        """Summary for the calibration file."""
        return {
            "period_us": round(float(self.period_us), 3),
            "n_on": len(self.on_us),
            "n_off": len(self.off_us),
            "half_window_us": round(self.half_window_us, 3),
            "strength": round(self.strength, 4),
            "step_snr": round(self.step_snr, 1) if math.isfinite(self.step_snr) else None,
            "first_on_us": round(self.on_us[0], 3) if self.on_us else None,
        }


def blink_level(t_us: np.ndarray, p: np.ndarray, bin_us: float) -> tuple[np.ndarray, float]:
    """Running sum of ON - OFF counts per bin of ``bin_us`` from the first event, linear trend removed.

    Returns:
        (level (n_bins,), t of the first bin's start, µs).
    """
    t0 = float(t_us[0])
    idx = ((t_us - t0) // bin_us).astype(np.int64)
    signed = np.bincount(idx, weights=2.0 * p.astype(np.float64) - 1.0)
    level = np.cumsum(signed)
    ramp = np.arange(len(level), dtype=np.float64)
    if len(level) > 1:
        slope, offset = np.polyfit(ramp, level, 1)
        level = level - (slope * ramp + offset)
    return level, t0


def _odd(width: float) -> int:
    """The odd integer nearest to ``width`` (>= 1): an odd running mean does not shift the series."""
    return max(1, 2 * int(round((width - 1) / 2)) + 1)


def _smooth(values: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return values
    kernel = np.ones(width) / width
    return np.convolve(np.pad(values, (width // 2, width - 1 - width // 2), mode="edge"), kernel, mode="valid")


def _autocorrelation(values: np.ndarray) -> np.ndarray:
    """Unbiased, normalised autocorrelation (lag 0 = 1) of a zero-mean series."""
    n = len(values)
    spec = np.fft.rfft(values - values.mean(), 2 * n)
    ac = np.fft.irfft(spec * np.conj(spec))[:n]
    ac = ac / np.arange(n, 0, -1)
    return ac / ac[0] if ac[0] > 0 else np.zeros(n)


def square_wave_period(ac: np.ndarray, min_lag: int, max_lag: int) -> float:
    """Lag (bins) maximising ``(ac(L) - ac(L/2)) / 2``, the smallest of the near-best (NaN: no room).

    The lag is then moved to the nearest local maximum of ``ac`` itself (a square wave's
    autocorrelation peaks exactly at its period), refined by a parabola.
    """
    lags = np.arange(max(min_lag, 2), min(max_lag, len(ac) - 1) + 1)
    if len(lags) < 3:
        return math.nan
    half = lags / 2.0
    lo = np.floor(half).astype(np.int64)
    ac_half = ac[lo] + (half - lo) * (ac[np.minimum(lo + 1, len(ac) - 1)] - ac[lo])
    score = 0.5 * (ac[lags] - ac_half)
    best = float(score.max())
    near = np.flatnonzero(score >= best - 0.1 * max(best, 0.0) - 1e-12)
    k = int(near[0])
    while k + 1 < len(score) and score[k + 1] >= score[k]:  # climb to the score's local peak
        k += 1
    j = int(lags[k])
    while 0 < j < len(ac) - 1 and max(ac[j - 1], ac[j + 1]) > ac[j]:  # then to ac's own peak
        j += 1 if ac[j + 1] > ac[j - 1] else -1
    lag = float(j)
    if 0 < j < len(ac) - 1:  # parabola through the peak
        a, b, c = ac[j - 1], ac[j], ac[j + 1]
        denom = a - 2 * b + c
        if denom < 0:
            lag += 0.5 * (a - c) / denom
    return lag


def detect_blink(t_us: np.ndarray, p: np.ndarray, search: BlinkSearch = BlinkSearch()) -> BlinkTiming:
    """Find the blink period and the switch times in time-sorted events.

    Args:
        t_us: (n,) event times, µs, sorted.
        p: (n,) polarities, 1 = ON.
        search: period range or the known period.

    Raises:
        CalibrationError: no events, a recording shorter than one period, or no blinking found.
    """
    if len(t_us) < 100:
        raise CalibrationError(f"only {len(t_us)} events: no blinking pattern recorded")
    duration_us = float(t_us[-1] - t_us[0])
    low = search.period_us if search.period_us is not None else search.min_period_us
    bin_us = max(1.0, low / 128.0, duration_us / _MAX_BINS)
    level, t0 = blink_level(t_us, p, bin_us)
    base_us = search.period_us if search.period_us is not None else search.min_period_us
    widths = (_odd(base_us / 6 / bin_us), _odd(base_us / 8 / bin_us))
    level = _smooth(_smooth(level, widths[0]), widths[1])
    margin = sum(widths) // 2  # samples this close to an end are distorted by the smoothing
    ac = _autocorrelation(level)
    if search.period_us is not None:
        lag = search.period_us / bin_us
    else:
        max_lag = int(min(search.max_period_us, duration_us / 1.25) / bin_us)
        lag = square_wave_period(ac, int(search.min_period_us / bin_us), max_lag)
        if not math.isfinite(lag):
            raise CalibrationError(
                f"recording of {duration_us / 1e6:.3f} s is too short to find a blink period of "
                f"{search.min_period_us / 1e6:g}-{search.max_period_us / 1e6:g} s (record at least 2 periods)"
            )
    grid = np.arange(len(ac))
    strength = 0.5 * float(np.interp(lag, grid, ac) - np.interp(lag / 2, grid, ac))
    if not strength >= search.min_strength:
        raise CalibrationError(
            f"no blinking pattern found: the event level is not a square wave (score {strength:.2f} < "
            f"{search.min_strength}; is the pattern blinking on and off, and in view?)"
        )
    period_us = lag * bin_us
    on = _refine_switches(level, bin_us, _find_steps(level, bin_us, period_us, +1.0, margin), period_us, +1.0, margin)
    off = _refine_switches(level, bin_us, _find_steps(level, bin_us, period_us, -1.0, margin), period_us, -1.0, margin)
    period_us = _fit_period(on, off, period_us)
    snr = _step_snr(level, bin_us, on, off, margin)
    if not snr >= search.min_step_snr:
        raise CalibrationError(
            f"no blinking pattern found: the event level has no clear steps (step {snr:.1f} x its spread < "
            f"{search.min_step_snr}; is the pattern blinking on and off, and in view?)"
        )
    gap = float(np.median([(t - on[0]) % period_us for t in off])) if on and off else period_us / 2
    half = 0.5 * min(gap, period_us - gap)
    first, last = float(t_us[0]) + half, float(t_us[-1]) - half
    on_us = tuple(float(t0 + t) for t in on if first <= t0 + t <= last)
    off_us = tuple(float(t0 + t) for t in off if first <= t0 + t <= last)
    if not on_us or not off_us:
        raise CalibrationError(
            f"recording of {duration_us / 1e6:.3f} s holds no full blink period of "
            f"{period_us / 1e6:.4f} s (record at least 2 periods)"
        )
    log.info(
        "blink period %.1f us (score %.2f, steps %.0f x spread), %d on / %d off switches",
        period_us,
        strength,
        snr,
        len(on_us),
        len(off_us),
    )
    return BlinkTiming(float(period_us), on_us, off_us, float(half), float(strength), float(snr))


def _step_snr(level: np.ndarray, bin_us: float, on_us: list[float], off_us: list[float], margin: int) -> float:
    """Median step between consecutive plateaus over the robust spread of the level on the plateaus.

    Plateaus are the spans between switches, less ``margin`` samples at each end (the smoothing's
    reach); a blink has flat plateaus, a random walk of noise events has not. Switch times are on
    the clock of :func:`_refine_switches`. Returns 0 when there are fewer than two plateaus of
    at least 5 samples (nothing to judge a blink by).
    """
    switches = sorted((t / bin_us - 1.0, sign) for sign, times in ((1.0, on_us), (-1.0, off_us)) for t in times)
    medians, spreads = [], []
    for (a, _), (b, _) in zip(switches[:-1], switches[1:], strict=True):
        lo, hi = int(math.ceil(a)) + margin, int(math.floor(b)) - margin
        if hi - lo < 4:
            return 0.0
        plateau = level[lo : hi + 1]
        medians.append(float(np.median(plateau)))
        spreads.append(np.abs(plateau - medians[-1]))
    if len(medians) < 2:
        return 0.0
    steps = [
        sign * (after - before)
        for (_, sign), before, after in zip(switches[1:-1], medians[:-1], medians[1:], strict=True)
    ]
    spread = 1.4826 * float(np.median(np.concatenate(spreads)))
    return float(np.median(steps)) / max(spread, 1e-9 * (float(np.max(np.abs(level))) + 1.0))


def _find_steps(level: np.ndarray, bin_us: float, period_us: float, sign: float, margin: int) -> list[int]:
    """Indices of the level's rises (sign +1) or falls (-1) over +-period/8: peaks of at least half
    the largest, at least 0.6 period apart (one switch of each kind per period), ``margin`` samples
    or more from the ends (where the smoothing distorts the level)."""
    reach = max(1, int(round(period_us / 8 / bin_us)))
    if len(level) <= 2 * (reach + margin) + 2:
        return []
    rise = sign * (level[2 * reach :] - level[: -2 * reach])  # rise[k]: across index k + reach
    rise[:margin] = rise[len(rise) - margin :] = -np.inf
    top = float(rise.max())
    if not top > 0:
        return []
    gap = int(0.6 * period_us / bin_us)
    found: list[int] = []
    for k in np.argsort(rise)[::-1]:  # strongest first, non-maximum suppression
        if rise[k] < 0.5 * top:
            break
        if all(abs(int(k) - f) >= gap for f in found):
            found.append(int(k))
    return sorted(k + reach for k in found)


def _refine_switches(
    level: np.ndarray, bin_us: float, centres: list[int], period_us: float, sign: float, margin: int
) -> list[float]:
    """Switch times: where the level crosses halfway between its values a period / 8 before and after
    each step centre (rising for sign +1, falling for -1), interpolated between samples.

    ``level[k]`` is the level at ``(k + 1) bin_us`` after the first bin's start; returned times are
    on that clock. Steps less than period / 8 + ``margin`` samples inside the data are left out.
    """
    reach = max(1, int(round(period_us / 8 / bin_us)))
    out = []
    for c in centres:
        lo, hi = c - reach, c + reach
        if lo < margin or hi > len(level) - 1 - margin:  # the step's neighbourhood is not all recorded
            continue
        rel = sign * (level[lo : hi + 1] - 0.5 * (level[lo] + level[hi]))
        crossings = np.flatnonzero((rel[:-1] < 0) & (rel[1:] >= 0))
        if not len(crossings):
            continue
        j = int(crossings[np.argmin(np.abs(crossings - reach))])
        out.append((lo + j + 1 - rel[j] / (rel[j + 1] - rel[j])) * bin_us)
    return out


def _fit_period(on_us: list[float], off_us: list[float], guess_us: float) -> float:
    """Least-squares period of switch times ``a_on + k T`` and ``a_off + k T`` (guess if too few)."""
    rows, values = [], []
    for column, times in enumerate((on_us, off_us)):
        if not times:
            continue
        k = np.round((np.asarray(times) - times[0]) / guess_us)
        for ki, ti in zip(k, times, strict=True):
            rows.append([ki, column == 0, column == 1])
            values.append(ti)
    if len(rows) < 3 or len({r[0] for r in rows}) < 2:
        return guess_us
    solution, *_ = np.linalg.lstsq(np.asarray(rows, dtype=np.float64), np.asarray(values), rcond=None)
    return float(solution[0])


def pseudo_image(events: np.ndarray, width: int, height: int, timing: BlinkTiming) -> np.ndarray:
    """Net ON - OFF counts around each switch-on minus around each switch-off, mean per switch.

    Each window has tapered ends (weight rising linearly over its first quarter, falling over its
    last): the net count is then the pixel's mean level just after the switch minus its mean level
    just before, so flicker cycles cut by the window's ends do not add up.

    Args:
        events: EVENT_DTYPE array sorted by time.
        width, height: sensor size, pixels (events outside are dropped).
        timing: from :func:`detect_blink`.

    Returns:
        (height, width) float64 image: about the number of events per switch on the lit parts, ~0 elsewhere.
    """
    t = events["t"]
    inside = (events["x"] < width) & (events["y"] < height)
    pixel = np.where(inside, events["y"].astype(np.int64) * width + events["x"], 0)
    signed = np.where(inside, 2.0 * events["p"] - 1.0, 0.0)
    half = timing.half_window_us
    total = np.zeros(width * height)
    for sign, times in ((1.0, timing.on_us), (-1.0, timing.off_us)):
        for t_switch in times:
            lo, hi = np.searchsorted(t, [t_switch - half, t_switch + half])
            taper = np.clip((half - np.abs(t[lo:hi] - t_switch)) / (0.5 * half), 0.0, 1.0)
            total += sign * np.bincount(pixel[lo:hi], weights=signed[lo:hi] * taper, minlength=width * height)
    n = len(timing.on_us) + len(timing.off_us)
    return (total / n).reshape(height, width)


def to_uint8(image: np.ndarray, percentile: float = 99.5) -> np.ndarray:
    """Pseudo-image scaled to 0..255 (negatives to 0, the ``percentile`` of lit pixels to 255)."""
    lit = image[image > 0]
    top = float(np.percentile(lit, percentile)) if lit.size else 1.0
    scaled = np.clip(image / max(top, 1e-12), 0.0, 1.0) * 255.0
    return np.round(scaled).astype(np.uint8)
