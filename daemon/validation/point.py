"""One sweep point checked against the point sensor: clock sync, e(t), its RMS and maximum, Delta_RMS(t).

Pure (numpy only): the supervisor calls :func:`validate_point` at the end of each point with what it
gathered, ``flagtrack validate`` with what the run's files hold; both get the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.pointsensor import (
    BeamParams,
    SensorComparison,
    beam_lateral,
    compare_signals,
    reading_to_lateral,
)
from flagtrack.daemon.core.sync import ClockSync, SyncParams, coarse_offset_us, trigger_sync, xcorr_sync
from flagtrack.drivers.sensor.record import SensorRecord


@dataclass(frozen=True)
class FlagFrame:
    """The flag's rest frame and length in the tracker's units."""

    length: float
    root: tuple[float, float]
    direction_deg: float


class SensorFields(TypedDict):
    """The sensor fields of a :class:`~flagtrack.daemon.sweep.runlog.PointResult` (same names and types)."""

    sensor_status: str
    sensor_error_rms_over_l: float
    sensor_error_max_over_l: float
    sensor_error_mean_over_l: float
    sensor_error_std_over_l: float
    sensor_sync: str
    sensor_offset_us: float
    sensor_offset_unc_us: float
    sensor_drift_ppm: float
    sensor_xcorr_offset_us: float
    sensor_xcorr_unc_us: float
    sensor_samples: int
    sensor_missing: int
    sensor_compared: int


@dataclass(frozen=True)
class PointValidation:
    """The point sensor against one point's reconstruction.

    Attributes:
        status: ``ok``, or why there is no comparison (``no sensor samples``, ``no centrelines``, ...).
        sync: the clock mapping used; trigger, xcorr, coarse: each estimate (method ``none`` if unavailable).
        comparison: e(t) at the sensor samples (None without a comparison).
        t_recon_s, y_recon: the reconstruction at the beam (camera clock, tracker units), every update.
        delta_rms: (n_t,) Delta_RMS of each update.
        frame: the flag's frame; units: tracker units; x_over_l: the beam's position.
        n_samples, n_missing: sensor samples received and lost.
        stale: (n_t,) bool, updates made without events that were left out of the comparison.
    """

    status: str
    sync: ClockSync
    trigger: ClockSync
    xcorr: ClockSync
    coarse: ClockSync
    comparison: SensorComparison | None
    t_recon_s: np.ndarray
    y_recon: np.ndarray
    delta_rms: np.ndarray
    frame: FlagFrame
    units: str
    x_over_l: float
    n_samples: int
    n_missing: int
    stale: np.ndarray

    @property
    def n_stale(self) -> int:
        """Updates left out of the comparison (made without events, flag flapping)."""
        return int(self.stale.sum())

    @property
    def cloud_distance_over_l(self) -> tuple[float, float]:
        """Time mean and standard deviation of the event-cloud distance Delta_RMS / L."""
        finite = self.delta_rms[np.isfinite(self.delta_rms)] / self.frame.length
        return (float(finite.mean()), float(finite.std())) if len(finite) else (math.nan, math.nan)

    def fields(self) -> SensorFields:
        """The sensor fields of a :class:`~flagtrack.daemon.sweep.runlog.PointResult`."""
        c = self.comparison
        nan = math.nan
        return {
            "sensor_status": self.status,
            "sensor_error_rms_over_l": c.error_rms_over_l if c else nan,
            "sensor_error_max_over_l": c.error_max_over_l if c else nan,
            "sensor_error_mean_over_l": c.abs_error_mean_over_l if c else nan,
            "sensor_error_std_over_l": c.abs_error_std_over_l if c else nan,
            "sensor_sync": self.sync.method,
            "sensor_offset_us": _num(self.sync.offset_us),
            "sensor_offset_unc_us": _num(self.sync.uncertainty_us),
            "sensor_drift_ppm": _num(self.sync.drift_ppm) if self.sync.ok else nan,
            "sensor_xcorr_offset_us": _num(self.xcorr.offset_us),
            "sensor_xcorr_unc_us": _num(self.xcorr.uncertainty_us),
            "sensor_samples": int(self.n_samples),
            "sensor_missing": int(self.n_missing),
            "sensor_compared": int(c.n_compared) if c else 0,
        }


def _num(value: float) -> float:
    return float(value) if math.isfinite(value) else math.nan


def camera_pulses(triggers: np.ndarray, params: SyncParams) -> np.ndarray:
    """Times (µs) of the camera trigger events the sync uses (channel and edge of ``params``)."""
    if len(triggers) == 0:
        return np.zeros(0, dtype=np.int64)
    keep = (triggers["channel"] == params.trigger_channel) & (triggers["edge"] == params.trigger_edge)
    return np.sort(triggers["t"][keep].astype(np.int64))


def synchronise(
    t_recon_s: np.ndarray,
    y_recon: np.ndarray,
    record: SensorRecord,
    y_sensor: np.ndarray,
    camera_pulses_us: np.ndarray,
    params: SyncParams,
) -> tuple[ClockSync, ClockSync, ClockSync, ClockSync]:
    """(used, trigger, xcorr, coarse) clock estimates for ``params.mode`` (see :mod:`~flagtrack.daemon.core.sync`)."""
    none = ClockSync("none", note="not attempted")
    coarse = coarse_offset_us(record.wall_t_us, record.wall_ns, record.camera_t_us, record.camera_wall_ns)
    if params.mode == "none":
        return ClockSync("none", 0.0, math.nan, note="sync mode 'none': one clock assumed"), none, none, coarse
    prior = coarse.offset_us if coarse.ok else 0.0
    xcorr = xcorr_sync(
        t_recon_s,
        y_recon,
        record.t_us,
        y_sensor,
        prior_offset_us=prior,
        max_lag_us=params.max_lag_ms * 1e3,
        min_correlation=params.min_correlation,
        blocks=params.blocks,
    )
    trigger = none
    if params.mode in ("auto", "trigger"):
        trigger = trigger_sync(
            camera_pulses_us,
            record.trigger_t_us,
            tolerance_us=params.tolerance_us,
            prior_offset_us=xcorr.offset_us if xcorr.ok else prior,
        )
    order = {"auto": (trigger, xcorr, coarse), "trigger": (trigger, coarse), "xcorr": (xcorr, coarse)}[params.mode]
    used = next((s for s in order if s.ok), ClockSync("none", note="no clock estimate: one clock assumed"))
    return used, trigger, xcorr, coarse


def validate_point(
    lines: CentrelineBatch | None,
    record: SensorRecord,
    triggers: np.ndarray,
    frame: FlagFrame,
    beam: BeamParams,
    params: SyncParams,
    units: str = "px",
    *,
    compare_without_events: bool = True,
) -> PointValidation:
    """Synchronise the sensor with the camera and compare it with the reconstruction at the beam.

    An update made without events carries the previous shape: right for a still flag, but during
    lost camera data (a flapping flag always gives events) it is no reconstruction at all. With
    ``compare_without_events`` False (the supervisor's choice for a flapping point) such updates
    are left out of e(t) and of the cross-correlation, and counted in ``n_stale``.

    Args:
        lines: the point's centrelines (camera clock), or None.
        record: the point's sensor samples, pulses and wall-clock stamps.
        triggers: the camera's trigger events during the point (TRIGGER_DTYPE).
        frame: the flag's rest frame and length (tracker units).
        beam: beam position and reading mapping.
        params: sync settings.
        units: tracker units (for figures).
        compare_without_events: compare the updates made without events too.
    """
    empty = np.zeros(0)
    none = ClockSync("none", note="not attempted")
    n_missing = int(max(record.missing, np.isnan(record.value).sum()))
    if lines is None or len(lines) == 0:
        return PointValidation(
            "no centrelines",
            none,
            none,
            none,
            none,
            None,
            empty,
            empty,
            empty,
            frame,
            units,
            beam.x_over_l,
            len(record.t_us),
            n_missing,
            np.zeros(0, dtype=bool),
        )
    y_recon = beam_lateral(lines.x, lines.y, frame.root, frame.direction_deg, beam.x_over_l * frame.length, beam.side)
    stale = np.zeros(len(lines), dtype=bool) if compare_without_events else (lines.n_events == 0)
    y_used = np.where(stale, np.nan, y_recon)
    base = (lines.t_s, y_recon, lines.delta_rms, frame, units, beam.x_over_l, len(record.t_us), n_missing, stale)
    if record.n_valid == 0:
        status = "no sensor samples" if len(record.t_us) == 0 and n_missing == 0 else "sensor samples all missing"
        return PointValidation(status, none, none, none, none, None, *base)
    y_sensor = reading_to_lateral(record.value, beam)
    used, trigger, xcorr, coarse = synchronise(
        lines.t_s, y_used, record, y_sensor, camera_pulses(triggers, params), params
    )
    t_cam_s = used.to_camera_us(record.t_us) * 1e-6
    comparison = compare_signals(
        lines.t_s, y_used, t_cam_s, y_sensor, frame.length, match_means=beam.zero_reading is None
    )
    if comparison.n_compared == 0:
        status = "no overlap" if np.any(np.isfinite(y_recon)) else "the centrelines do not reach the beam"
    else:
        status = "ok" if used.method in ("trigger", "xcorr") else f"ok, unsynchronised ({used.method})"
    return PointValidation(status, used, trigger, xcorr, coarse, comparison if comparison.n_compared else None, *base)
