"""What a sweep point's recording found, from what the supervisor's monitor gathered meanwhile: the
flag's state, the centrelines' metrics, the point-sensor comparison (a run's
:class:`~flagtrack.daemon.sweep.ports.PointMeasure`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.services.supervisor.analysis import PointMetrics, point_metrics
from flagtrack.daemon.services.supervisor.monitor import BusMonitor, Collection, point_state
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.runlog import POINTS_DIR, PointResult, point_paths


@dataclass(frozen=True)
class FlagGeometry:
    """The flag's rest frame and length in the tracker's units (for A/L and the lateral displacement)."""

    length: float
    root: tuple[float, float]
    direction_deg: float


class BusMeasure:
    """Gathers a point's rates and centrelines with the monitor; judges them at the end.

    Args:
        monitor: the supervisor's subscriptions.
        flag: the flag's geometry.
        sensor: a point sensor (``SensorConfig``) compared with each point's reconstruction, or None.
    """

    def __init__(self, monitor: BusMonitor, flag: FlagGeometry, sensor: Any = None) -> None:
        self.monitor, self.flag, self.sensor = monitor, flag, sensor
        self._gathered = Collection()

    def begin(self) -> None:
        self.monitor.start_collecting()

    def end(self) -> None:
        self._gathered = self.monitor.stop_collecting()

    def result(self, point: Point, run_dir: Path, previous_state: str) -> PointResult:
        collection = self._gathered
        on_hz, off_hz = self.monitor.thresholds_hz()
        state = point_state(collection.rates_hz, on_hz, off_hz, previous_state)
        metrics = point_metrics(collection.batches, self.flag.length, self.flag.root, self.flag.direction_deg)
        if state != "flapping":  # a still flag has no amplitude or frequency worth a number
            metrics = PointMetrics(
                amplitude_over_l=metrics.amplitude_over_l,
                delta_rms_over_l=metrics.delta_rms_over_l,
                updates=metrics.updates,
                delta_rms_std_over_l=metrics.delta_rms_std_over_l,
                lost_fraction=metrics.lost_fraction,
                shed_fraction=metrics.shed_fraction,
                stale_fraction=metrics.stale_fraction,
            )
        return PointResult.planned(
            point,
            state=state,
            amplitude_over_l=metrics.amplitude_over_l,
            amplitude_std_over_l=metrics.amplitude_std_over_l,
            frequency_hz=metrics.frequency_hz,
            twi=metrics.twi,
            cloud_distance_mean_over_l=metrics.delta_rms_over_l,
            event_rate_mev_s=float(np.mean(collection.rates_hz)) / 1e6 if collection.rates_hz else math.nan,
            cloud_distance_std_over_l=metrics.delta_rms_std_over_l,
            lost_fraction=metrics.lost_fraction,
            shed_fraction=metrics.shed_fraction,
            stale_fraction=metrics.stale_fraction,
            **self._check_sensor(point, run_dir, collection, state),
        )

    def _check_sensor(self, point: Point, run_dir: Path, collection: Collection, state: str) -> dict[str, Any]:
        """The point-sensor fields of the point (empty without a sensor); never raises."""
        if self.sensor is None:
            return {}
        from flagtrack.daemon.services.supervisor.sensor_check import check_point
        from flagtrack.daemon.validation.point import FlagFrame

        base = run_dir / POINTS_DIR / point.point_id
        raw = run_dir / point_paths(point.point_id)[0]
        frame = FlagFrame(self.flag.length, self.flag.root, self.flag.direction_deg)
        title = f"run {run_dir.name}, point {point.point_id}: {point.speed_mps:.2f} m/s, {state}"
        return check_point(base, run_dir, collection, raw, frame, self.sensor, state, title)
