"""The ``tracker:`` section and its calibration, turned once into what trackers and files need."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flagtrack.daemon.tracking.section import TrackingConfig, load_tracking_config

if TYPE_CHECKING:
    from flagtrack.daemon.core.mapping import PointMapping
    from flagtrack.daemon.core.tracker import Tracker, TrackerParams


@dataclass(frozen=True)
class TrackingSetup:
    """A checked tracking set-up.

    Attributes:
        config: the ``tracker:`` section it was made from.
        params: the core tracker's parameters.
        mapping: the pixel -> plane mapping of the calibration, or None (pixels).
        units: ``px``, or the mapping's units (``m``).
        attrs: what every centreline file made with it carries: every processing parameter, the
            calibration's attributes when there is one, and ``units``.
    """

    config: TrackingConfig
    params: TrackerParams
    mapping: PointMapping | None
    units: str
    attrs: dict[str, Any]

    def new_tracker(self, sensor_size: tuple[int, int] = (0, 0)) -> Tracker:
        """A fresh core tracker (``sensor_size``: width, height in pixels, 0 if unknown)."""
        from flagtrack.daemon.core.tracker import Tracker

        return Tracker(self.params, mapping=self.mapping, sensor_size=sensor_size)

    @property
    def factory(self) -> Callable[[], Tracker]:
        """Fresh core trackers, for a live service (one per camera stream)."""
        return self.new_tracker


def tracking_setup(config: TrackingConfig, *, path: str | None = None) -> TrackingSetup:
    """Check ``config`` (root, length, ranges, the calibration file) and prepare the core.

    Args:
        config: the ``tracker:`` section (a relative calibration path already resolved).
        path: the config file, named in errors.

    Raises:
        ConfigError: a missing or out-of-range value, naming the key and the file.
        FormatError: the calibration file is not one.
    """
    params = config.tracker_params(path=path)
    mapping: PointMapping | None = None
    if config.calibration is not None:
        from flagtrack.calibration.calfile import load_mapping

        mapping = load_mapping(config.calibration)
    units = "px" if mapping is None else getattr(mapping, "units", "m")
    return TrackingSetup(config, params, mapping, units, {**processing_attrs(config), "units": units})


def processing_attrs(config: TrackingConfig) -> dict[str, Any]:
    """How a centreline file was made: every parameter of ``config`` and its calibration's attributes.

    Unlike :func:`tracking_setup`, the section is not checked (a recorder keeps the attributes of
    the tracker that sends it centrelines, whose section may leave the root to another host).

    Raises:
        ConfigError, FormatError: the calibration file cannot be read.
    """
    attrs = config.attrs()
    if config.calibration is not None:
        from flagtrack.calibration.calfile import calibration_attrs

        attrs.update(calibration_attrs(config.calibration))
    return attrs


def load_tracking_config_file(path: str | Path) -> TrackingConfig:
    """The ``tracker:`` section of ``path``; a relative calibration file is taken from the file's folder."""
    return resolve_calibration(load_tracking_config(path), Path(path).parent)


def resolve_calibration(config: TrackingConfig, base: Path) -> TrackingConfig:
    """``config`` with a relative ``calibration`` path made relative to ``base`` (the config's folder)."""
    if config.calibration is not None and not Path(config.calibration).is_absolute():
        return config.with_overrides(calibration=Path(base) / config.calibration)
    return config


def root_on_sensor(setup: TrackingSetup, width: int, height: int) -> bool:
    """Whether the root lies on a ``width`` x ``height`` sensor (pixel centres at whole coordinates;
    with a calibration, inside the sensor's outline mapped to the plane)."""
    x, y = setup.params.chain.root
    if setup.mapping is None:
        return bool(-0.5 <= x <= width - 0.5 and -0.5 <= y <= height - 0.5)
    u = np.linspace(-0.5, width - 0.5, 65)
    v = np.linspace(-0.5, height - 0.5, 65)
    px = np.concatenate([u, np.full(65, width - 0.5), u[::-1], np.full(65, -0.5)]).astype(np.float32)
    py = np.concatenate([np.full(65, -0.5), v, np.full(65, height - 0.5), v[::-1]]).astype(np.float32)
    ox, oy = (np.asarray(a, dtype=np.float64) for a in setup.mapping.map(px, py))
    if not (np.isfinite(ox).all() and np.isfinite(oy).all()):
        return True  # an outline the mapping cannot place: no verdict
    x0, y0, x1, y1 = ox, oy, np.roll(ox, -1), np.roll(oy, -1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return bool(np.count_nonzero(crosses & (x < at)) % 2)
