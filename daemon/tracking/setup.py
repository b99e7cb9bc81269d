"""The ``tracker:`` section and its calibration, turned once into what trackers and files need."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

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


def calibration_misfit(mapping: PointMapping | None, width: int, height: int, sensor: str) -> str | None:
    """Why ``mapping`` cannot serve the ``width`` x ``height`` sensor of ``sensor`` (it was made on
    another size), or None (it can, or a size is unknown)."""
    made_on = getattr(mapping, "image_size", None)
    if made_on is None or not width or not height or tuple(made_on) == (width, height):
        return None
    return (
        f"made on a {made_on[0]} x {made_on[1]} sensor, not the {width} x {height} sensor of {sensor}: its "
        "pixels would map to the wrong places (calibrate this camera: flagtrack calibrate)"
    )


def refuse_tracker_off_sensor(
    config: TrackingConfig, width: int, height: int, *, sensor: str, path: str | None
) -> None:
    """Refuse a calibration made on a sensor of another size than ``width`` x ``height`` (``sensor``
    says whose), and a ``tracker.root`` off that sensor, through the calibration when there is one;
    nothing to say without a root or with a calibration not made yet.

    Raises:
        ConfigError: naming ``tracker.calibration`` or ``tracker.root``, and ``path``.
        FormatError: the calibration file is not one.
    """
    from flagtrack.daemon.core.mapping import on_sensor
    from flagtrack.daemon.errors import ConfigError

    if config.calibration is not None and not Path(config.calibration).is_file():
        return
    mapping: PointMapping | None = None
    if config.calibration is not None:
        from flagtrack.calibration.calfile import load_mapping

        mapping = load_mapping(config.calibration)
        misfit = calibration_misfit(mapping, width, height, sensor)
        if misfit is not None:
            raise ConfigError(f"{config.calibration}: {misfit}", key="tracker.calibration", path=path)
    if config.root is None or not all(math.isfinite(v) for v in config.root):
        return  # (no root, or not a place: the range checks name it)
    x, y = config.root
    if not on_sensor(x, y, width, height, mapping):
        plane = " (its outline mapped through the calibration)" if mapping is not None else ""
        raise ConfigError(
            f"({x:g}, {y:g}) is off the {width} x {height} sensor of {sensor}{plane}: nothing there to track",
            key="tracker.root",
            path=path,
        )


def load_tracking_config_file(path: str | Path) -> TrackingConfig:
    """The ``tracker:`` section of ``path``; a relative calibration file is taken from the file's folder."""
    return resolve_calibration(load_tracking_config(path), Path(path).parent)


def resolve_calibration(config: TrackingConfig, base: Path) -> TrackingConfig:
    """``config`` with a relative ``calibration`` path made relative to ``base`` (the config's folder)."""
    if config.calibration is not None and not Path(config.calibration).is_absolute():
        return config.with_overrides(calibration=Path(base) / config.calibration)
    return config


def root_on_sensor(setup: TrackingSetup, width: int, height: int) -> bool:
    """Whether the root lies on a ``width`` x ``height`` sensor (:func:`.core.mapping.on_sensor`)."""
    from flagtrack.daemon.core.mapping import on_sensor

    x, y = setup.params.chain.root
    return on_sensor(x, y, width, height, setup.mapping)
