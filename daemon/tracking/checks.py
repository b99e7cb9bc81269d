"""Range checks of the ``tracker:`` section, each naming its key, before any work is done.

Every number that reaches the compiled tracker is checked here: finite, in a range where the
tracker gives an answer in bounded time and memory (the ranges are stated in the messages).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from flagtrack.daemon.core.windows import MAX_ABS_TIME_S
from flagtrack.daemon.errors import ConfigError

SECTION = "tracker"
# the core's own limits (checked there too), named here by key: joints, link lengths, ds, tau/dt, times
MAX_JOINTS, MAX_LINK_RATIO = 1000, 1000.0
MAX_SAMPLES = 100_001
TIME_RANGE_S = (1e-6, 3600.0)
MAX_COORDINATE = 1e9  # root and length, in pixels or plane units (1e308: the loss settings overflowed)


def check_tracking_config(config: Any, *, path: str | None = None) -> None:
    """Raise :class:`ConfigError` naming the first key of ``config`` (a ``TrackingConfig``) out of its range."""

    def fail(key: str, message: str) -> None:
        raise ConfigError(message, key=f"{SECTION}.{key}", path=path)

    if config.root is not None:
        root = tuple(config.root)
        if len(root) != 2 or not all(_finite(v) and abs(v) <= MAX_COORDINATE for v in root):
            fail("root", f"must be two finite numbers (x, y) of at most {MAX_COORDINATE:g}, got {_show(root)}")
    if config.length is not None and not (_finite(config.length) and 0 < config.length <= MAX_COORDINATE):
        fail("length", f"must be a positive finite number of at most {MAX_COORDINATE:g}, got {config.length}")
    if not _finite(config.direction_deg):
        fail("direction_deg", f"must be a finite number of degrees, got {config.direction_deg}")
    if not 1 <= config.joints <= MAX_JOINTS:
        fail("joints", f"must be 1-{MAX_JOINTS} links, got {config.joints}")
    if config.link_lengths is not None:
        _check_links(config, fail)
    if not (_finite(config.alpha) and 0 < config.alpha < 1):
        fail("alpha", f"must be in (0, 1), got {config.alpha}")
    if not (_finite(config.angle_limit_deg) and 0 < config.angle_limit_deg <= 180):
        fail("angle_limit_deg", f"must be in (0, 180] degrees, got {config.angle_limit_deg}")
    _check_times(config, fail)
    _check_rest(config, fail)


def _check_rest(config: Any, fail: Any) -> None:
    if config.ds is not None and config.length is not None:
        lo = config.length / (MAX_SAMPLES - 1)
        if not (_finite(config.ds) and lo <= config.ds <= config.length):
            fail("ds", f"must be in [L / {MAX_SAMPLES - 1}, L] = [{lo:g}, {config.length:g}], got {config.ds}")
    elif config.ds is not None and not (_finite(config.ds) and config.ds > 0):
        fail("ds", f"must be a positive finite number, got {config.ds}")
    if not (_finite(config.refine_deg) and 0 < config.refine_deg <= 180):
        fail("refine_deg", f"must be in (0, 180] degrees, got {config.refine_deg}")
    if config.max_gap_s is not None and not (config.max_gap_s > 0 and not math.isnan(config.max_gap_s)):
        fail("max_gap_s", f"must be positive (or null), got {config.max_gap_s}")


def _check_links(config: Any, fail: Any) -> None:
    links = tuple(config.link_lengths or ())
    if not all(_finite(v) and v > 0 for v in links):
        fail("link_lengths", f"must be positive finite numbers, got {_show(links)}")
    if links and max(links) > MAX_LINK_RATIO * min(links):
        fail("link_lengths", f"the longest may be at most {MAX_LINK_RATIO:g} times the shortest, got {_show(links)}")


def _check_times(config: Any, fail: Any) -> None:
    lo, hi = TIME_RANGE_S
    for key, value in (("tau_s", config.tau_s), ("dt_s", config.dt_s)):
        if value is not None and not (_finite(value) and lo <= value <= hi):
            fail(key, f"must be in [{lo:g}, {hi:g}] s, got {value}")
    for i, seg in enumerate(config.schedule):
        for name in ("dt_s", "tau_s"):
            value = getattr(seg, name)
            if not (_finite(value) and lo <= value <= hi):
                fail(f"schedule[{i}].{name}", f"must be in [{lo:g}, {hi:g}] s, got {value}")
        if not (_finite(seg.t_from_s) and abs(seg.t_from_s) <= MAX_ABS_TIME_S):
            fail(f"schedule[{i}].t_from_s", f"must be a finite time within +-{MAX_ABS_TIME_S:g} s, got {seg.t_from_s}")
    for key in ("t_start_s", "t_stop_s"):
        value = getattr(config, key)
        if value is not None and not (_finite(value) and abs(value) <= MAX_ABS_TIME_S):
            fail(key, f"must be a finite time within +-{MAX_ABS_TIME_S:g} s, got {value}")
    if config.t_start_s is not None and config.t_stop_s is not None and not config.t_start_s < config.t_stop_s:
        fail("t_start_s", f"must be before the stop time, got {config.t_start_s} >= {config.t_stop_s}")


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _show(values: Iterable[Any]) -> str:
    return "[" + ", ".join(str(v) for v in values) + "]"
