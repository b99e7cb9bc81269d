"""What a sweep point's recording found, from what the supervisor's monitor gathered meanwhile: the
flag's state, the centrelines' metrics, the point-sensor comparison (a run's
:class:`~flagtrack.daemon.sweep.ports.PointMeasure`)."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flagtrack.daemon.services.supervisor.analysis import PointMetrics, point_metrics
from flagtrack.daemon.services.supervisor.monitor import BusMonitor, Collection, point_state
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.runlog import POINTS_DIR, PointResult, point_paths

if TYPE_CHECKING:
    from flagtrack.daemon.tracking.setup import TrackingSetup

log = logging.getLogger(__name__)


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
        tracking: the rig's tracking set-up: with it, a flapping point's live centrelines are set
            against the first events of its recording (``chain_reach``); None: not judged.
    """

    def __init__(
        self, monitor: BusMonitor, flag: FlagGeometry, sensor: Any = None, tracking: TrackingSetup | None = None
    ) -> None:
        self.monitor, self.flag, self.sensor, self.tracking = monitor, flag, sensor, tracking
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
            chain_reach=self._chain_reach(point, run_dir, collection) if state == "flapping" else math.nan,
            **self._check_sensor(point, run_dir, collection, state),
        )

    def _chain_reach(self, point: Point, run_dir: Path, collection: Collection) -> float:
        """Where the flag's events ended along the live chain over the point's first events (NaN: not
        judged); a chain off the flag's length is said in the log. Never raises."""
        raw = run_dir / point_paths(point.point_id)[0]
        if self.tracking is None or not collection.batches or not raw.exists():
            return math.nan
        from flagtrack.daemon.core.centreline import CentrelineBatch
        from flagtrack.daemon.tracking.reach import recording_reach

        try:
            reach = recording_reach(raw, CentrelineBatch.concatenate(collection.batches), self.tracking)
        except Exception as exc:  # noqa: BLE001 - a figure of the point, not a reason to stop the sweep
            log.warning("point %s: the chain's reach was not judged: %s", point.point_id, exc)
            return math.nan
        if reach is None:
            return math.nan
        misfit = reach.misfit(self.tracking.params.chain.length, self.tracking.units)
        if misfit:
            log.warning(
                "point %s: %s: check tracker.length (and the root); the point is suspect", point.point_id, misfit
            )
        return reach.reach

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
