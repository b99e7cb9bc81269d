"""``camera.hardware``'s automatic settings, worked out from the rest of the rig before the adapter
sees them (an adapter receives plain settings only).

- ``roi: auto``: the smallest rectangle of pixels holding the flag's reach (:mod:`flagtrack.daemon.core.reach`)
  from the ``tracker:`` section (root, rest direction, length, links, alpha, and the calibration when
  the geometry is in plane units), grown by ``roi_margin_over_l`` of the length, within
  ``roi_half_angle_deg`` of the rest direction; cut at the sensor's edges when the camera opens.
- ``rate_limiter: auto`` (``prophesee``) or ``rate_limiter_events_per_s: auto`` (``metavision``): the
  sensor's event rate controller set to ``rate_margin`` times the rate the flag is expected to
  give (``supervisor.expected_rate_mev_s``), and never below ``rate_margin`` times what the tracker
  needs to judge a window (``tracker.lost.min_events`` per ``tracker.tau_s``).

Each value set comes with a line saying what and why (:attr:`AutoSettings.why`), which the camera's
status (``settings.auto``) and the log repeat.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from flagtrack.daemon.core.reach import PixelBox, Reach, pixel_box, search_radius
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.sections import RigSections
from flagtrack.daemon.tracking.section import TrackingConfig

KEY = "camera.hardware"
OPTIONS = {"roi_margin_over_l": 0.1, "roi_half_angle_deg": 90.0, "rate_margin": 2.0}
"""The keys that say how the automatic values are worked out (removed before the adapter sees the
settings), with their defaults."""
RATE_KEYS = {"prophesee": "rate_limiter", "metavision": "rate_limiter_events_per_s"}
"""Each adapter's rate-limiter key, which takes ``auto``."""
ERC_PERIOD_US = 200
"""Reference period of an automatic neuromorphic-drivers rate limiter (its count is per period)."""


@dataclass(frozen=True)
class AutoSettings:
    """``camera.hardware`` with its automatic values worked out.

    Attributes:
        hardware: the plain settings for the adapter.
        why: for each key set automatically, what it was set to and why (one line).
    """

    hardware: dict[str, Any]
    why: dict[str, str] = field(default_factory=dict)


def resolve_auto(rig: RigSections) -> AutoSettings:
    """Work out ``roi: auto`` and the rate limiter's ``auto`` of ``rig.camera.hardware``.

    Raises:
        ConfigError: naming ``camera.hardware.<key>`` and the rig file: an option without its
            ``auto``, a value out of range, a geometry that leaves no pixel of the sensor in reach.
    """
    hardware = dict(rig.camera.hardware)
    options = {name: _option(hardware.pop(name), name, rig.path) for name in OPTIONS if name in hardware}
    settings = {**OPTIONS, **options}
    why: dict[str, str] = {}
    if hardware.get("roi") == "auto":
        box, why["roi"] = auto_roi(rig.tracker, settings["roi_margin_over_l"], settings["roi_half_angle_deg"], rig.path)
        hardware["roi"] = {**box.as_dict(), "clip": True}
    rate_key = RATE_KEYS.get(rig.camera.adapter)
    if rate_key is not None and hardware.get(rate_key) == "auto":
        hardware[rate_key], why[rate_key] = auto_rate(rig, rig.camera.adapter, settings["rate_margin"])
    for name in options:
        used = (rate_key in why) if name == "rate_margin" else ("roi" in why)
        if not used:
            wanted = f"{rate_key}: auto" if name == "rate_margin" and rate_key else "roi: auto"
            raise ConfigError(f"only used with {wanted}", key=f"{KEY}.{name}", path=rig.path)
    return AutoSettings(hardware, why)


def auto_roi(
    tracker: TrackingConfig, margin_over_l: float, half_angle_deg: float, path: str | None
) -> tuple[PixelBox, str]:
    """The ROI of ``roi: auto`` and why, from the ``tracker:`` section.

    Raises:
        ConfigError: naming ``camera.hardware.roi``: no geometry, or no pixel of the sensor in reach.
    """
    key = f"{KEY}.roi"
    if tracker.root is None or tracker.length is None:
        raise ConfigError("auto needs the flag's geometry: set tracker.root and tracker.length", key=key, path=path)
    mapping, image_size, units = None, None, "px"
    if tracker.calibration is not None:
        from flagtrack.calibration.calfile import load_mapping

        mapping = load_mapping(tracker.calibration)
        image_size, units = mapping.image_size, mapping.units
    radius = search_radius(tracker.length, tracker.link_lengths, tracker.joints, tracker.alpha)
    try:
        reach = Reach(tracker.root, radius, tracker.direction_deg, half_angle_deg, margin_over_l * tracker.length)
    except ValueError as exc:
        raise ConfigError(
            f"auto: {exc} (from tracker.root, tracker.length, tracker.direction_deg)", key=key, path=path
        ) from None
    box = pixel_box(reach, mapping, image_size)
    where = f"tracker.root ({tracker.root[0]:g}, {tracker.root[1]:g}) {units}"
    if box is None:
        raise ConfigError(f"auto: no pixel of the sensor is within the flag's reach around {where}", key=key, path=path)
    sector = (
        "disc" if half_angle_deg >= 180 else f"sector of ±{half_angle_deg:g} degrees about {tracker.direction_deg:g}"
    )
    text = (
        f"columns {box.x}..{box.x + box.width - 1}, rows {box.y}..{box.y + box.height - 1}: the flag's reach, a "
        f"{sector} of radius {radius / tracker.length:.2f} L = {radius:.4g} {units} around {where} (the chain's "
        f"search areas and the background ring of its loss-of-track verdict) plus {margin_over_l:g} L"
        + (" (through the calibration)" if mapping is not None else "")
        + "; rows and columns outside are masked"
    )
    return box, text


def auto_rate(rig: RigSections, adapter: str, margin: float) -> tuple[Any, str]:
    """The rate limiter of ``auto`` for ``adapter`` (its key's value) and why."""
    expected = rig.supervisor.expected_rate_mev_s * 1e6
    needed = rig.tracker.lost.min_events / rig.tracker.tau_s
    rate = margin * max(expected, needed)
    basis = (
        f"supervisor.expected_rate_mev_s ({expected / 1e6:g} Mev/s)"
        if expected >= needed
        else f"the {needed / 1e6:.3g} Mev/s the tracker needs (tracker.lost.min_events per tracker.tau_s)"
    )
    text = (
        f"{rate / 1e6:.4g} Mev/s = {margin:g} x {basis}: a burst beyond it is dropped by the sensor, "
        "not by the USB link or the host"
    )
    if adapter == "prophesee":
        count = max(1, math.ceil(rate * ERC_PERIOD_US * 1e-6))
        return {"reference_period_us": ERC_PERIOD_US, "maximum_events_per_period": count}, (
            f"{count} events per {ERC_PERIOD_US} µs, {text}"
        )
    return math.ceil(rate), text


def _option(value: Any, name: str, path: str | None) -> float:
    """An option's value, checked: a number within its range."""
    key = f"{KEY}.{name}"
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"must be a number, got {value!r}", key=key, path=path)
    limits = {"roi_margin_over_l": (0.0, 10.0), "roi_half_angle_deg": (1.0, 180.0), "rate_margin": (1.0, 1000.0)}
    low, high = limits[name]
    if not low <= value <= high:
        raise ConfigError(f"must be in [{low:g}, {high:g}], got {value:g}", key=key, path=path)
    return float(value)
