"""Recompute the point-sensor comparison of a finished sweep from its files (``flagtrack validate``).

For every point with a sensor record: the centrelines (the run's own, another folder's, or a new
reconstruction of the raw file), the camera's trigger events from the raw file, and the sensor
record go through the same :func:`~flagtrack.daemon.validation.point.validate_point` as live.
Results go to ``RUN_DIR/validation/`` (or ``out_dir``): one figure per point, ``validation.csv``
(the summary's columns, with the recomputed sensor and Delta_RMS/L numbers) and ``validation.png``.
A point whose files cannot be read (damaged, cut, missing) is said in one line and gets the status
``damaged: <file: why>``; the other points go on. The run log is never rewritten.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flagtrack.daemon.core.events import empty_triggers
from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.sweep.figures import plot_sweep
from flagtrack.daemon.sweep.runlog import RUN_LOG, PointResult, read_run
from flagtrack.daemon.sweep.summary import run_caption, write_summary_csv
from flagtrack.daemon.tracking.offline import reconstruct_file
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.tracking.setup import TrackingSetup, load_tracking_config_file
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.daemon.validation.collect import raw_triggers
from flagtrack.daemon.validation.figures import plot_point
from flagtrack.daemon.validation.point import FlagFrame, PointValidation, SensorFields, validate_point
from flagtrack.drivers.sensor.record import read_sensor_record
from flagtrack.drivers.sensor.setup import SensorConfig

log = logging.getLogger(__name__)

VALIDATION_DIR = "validation"

DAMAGED = "damaged: "
"""The start of the status of a point whose files could not be read (then the file and why)."""


@dataclass(frozen=True)
class RunValidation:
    """What :func:`validate_run` wrote: the points (recomputed), the table, the figures."""

    points: list[PointResult]
    csv: Path
    figure: Path
    point_figures: dict[str, Path]

    @property
    def damaged(self) -> list[PointResult]:
        """The points not validated because their files could not be read (status ``damaged: ...``)."""
        return [p for p in self.points if (p.sensor_status or "").startswith(DAMAGED)]


def run_sensor_config(record: Any, path: str) -> SensorConfig:
    """The ``sensor:`` section stored in a run's start record.

    Raises:
        FormatError: the run was made without a sensor (or its section is invalid).
    """
    config = record.start.get("config", {})
    if not isinstance(config, dict) or not config.get("sensor"):
        raise FormatError("the run has no 'sensor' section in its start record (made without a sensor)", path=path)
    try:
        return from_mapping(SensorConfig, config["sensor"], path=path, key="config.sensor")
    except ConfigError as exc:
        raise FormatError(f"stored sensor config is invalid: {exc}", path=path) from exc


def run_tracking_config(record: Any, config_file: Path | None = None) -> tuple[TrackingConfig, str]:
    """The ``tracker:`` section a run's points are reconstructed with, and where it was read: the
    ``config_file``'s if one is given (``-c``), else the one stored in the run's start record."""
    if config_file is not None:
        return load_tracking_config_file(config_file), str(config_file)
    where = str(record.run_dir / RUN_LOG)
    stored = record.start.get("config", {}).get("tracker") or {}
    return from_mapping(TrackingConfig, stored, path=where, key="config.tracker"), where


def run_frame(record: Any) -> FlagFrame:
    """The flag's rest frame and length from the run's ``tracker:`` section (as the supervisor takes it)."""
    tracker = record.start.get("config", {}).get("tracker", {}) or {}
    root = tracker.get("root") or (0.0, 0.0)
    return FlagFrame(
        float(tracker.get("length") or 1.0),
        (float(root[0]), float(root[1])),
        float(tracker.get("direction_deg") or 0.0),
    )


def validate_run(
    run_dir: str | Path,
    *,
    out_dir: str | Path | None = None,
    centrelines_dir: str | Path | None = None,
    sensor: SensorConfig | None = None,
    reconstruct: TrackingSetup | None = None,
    window_s: float = 0.3,
) -> RunValidation:
    """Recompute every point's sensor comparison (see the module docstring).

    Args:
        run_dir: the run folder.
        out_dir: where results go (default ``RUN_DIR/validation``).
        centrelines_dir: take each point's centrelines from ``DIR/<point_id>_centrelines.h5`` (or
            ``DIR/<point_id>.h5``) instead of the run's own.
        sensor: the sensor config to use (default: the run's own, e.g. with another ``sync`` or ``beam``).
        reconstruct: a tracking set-up: reconstruct each raw file with it first (into ``out_dir/centrelines``).
        window_s: time shown in each point's figure.
    """
    run_dir = Path(run_dir)
    record = read_run(run_dir)
    sensor = sensor or run_sensor_config(record, str(run_dir / RUN_LOG))
    frame = run_frame(record)
    out = Path(out_dir) if out_dir is not None else run_dir / VALIDATION_DIR
    out.mkdir(parents=True, exist_ok=True)
    points, figures = [], {}
    for point in record.latest_points().values():
        if point.sensor_file is None:
            points.append(point)
            continue
        try:
            updated, figure = _validate_one(run_dir, point, out, frame, sensor, centrelines_dir, reconstruct,
                                            window_s, str(record.start.get("run_id", "?")))  # fmt: skip
        except (FormatError, OSError) as exc:  # this point's files: the others go on
            log.warning("validate: point %s not validated: %s", point.point_id, exc)
            updated, figure = _not_validated(point, f"{DAMAGED}{exc}"), None
        points.append(updated)
        if figure is not None:
            figures[point.point_id] = figure
    csv = write_summary_csv(points, out / "validation.csv")
    title = "Point-sensor error and event-cloud distance against the wind speed (paper fig. 5g), recomputed\n"
    title += run_caption(record, points)
    figure = plot_sweep(points, out / "validation.png", title)
    return RunValidation(points, csv, figure, figures)


def _not_validated(point: PointResult, status: str) -> PointResult:
    """``point`` with ``status`` and none of the live run's comparison figures (they were not recomputed)."""
    names = {*SensorFields.__annotations__, "cloud_distance_mean_over_l", "cloud_distance_std_over_l"}
    defaults: dict[str, Any] = {f.name: f.default for f in dataclasses.fields(PointResult) if f.name in names}
    return dataclasses.replace(point, **{**defaults, "sensor_status": status})


def _validate_one(
    run_dir: Path,
    point: PointResult,
    out: Path,
    frame: FlagFrame,
    sensor: SensorConfig,
    centrelines_dir: str | Path | None,
    reconstruct: TrackingSetup | None,
    window_s: float,
    run_id: str = "?",
) -> tuple[PointResult, Path | None]:
    raw = run_dir / point.raw_file if point.raw_file else None
    lines_path = _centrelines_path(run_dir, point, out, centrelines_dir, reconstruct, raw)
    if lines_path is None or not lines_path.exists():
        return dataclasses.replace(point, sensor_status="no centrelines file"), None
    validation = point_validation(run_dir, point, lines_path, frame, sensor)
    figure = plot_point(
        validation,
        out / f"{point.point_id}.png",
        f"run {run_id}, point {point.point_id}: {point.speed_mps:.2f} m/s, {point.state} (recomputed)",
        window_s,
    )
    d_mean, d_std = validation.cloud_distance_over_l
    checked = dataclasses.replace(
        point,
        **validation.fields(),
        cloud_distance_mean_over_l=d_mean,
        cloud_distance_std_over_l=d_std,
        centreline_file=_relative(lines_path, run_dir),
        sensor_figure=_relative(figure, run_dir),
    )
    return checked, figure


def point_validation(
    run_dir: Path, point: PointResult, lines_path: Path, frame: FlagFrame, sensor: SensorConfig
) -> PointValidation:
    """The sensor comparison of one point of a run from its files: the centrelines of ``lines_path``,
    the point's sensor record and the trigger events of its raw file."""
    from flagtrack.drivers.formats.centreline import read_centrelines

    raw = run_dir / point.raw_file if point.raw_file else None
    lines, attrs = read_centrelines(lines_path)
    record = read_sensor_record(run_dir / point.sensor_file)  # type: ignore[operator]
    triggers = empty_triggers()
    if sensor.sync.mode in ("auto", "trigger") and len(record.trigger_t_us):
        if raw is not None and raw.exists():
            triggers = raw_triggers(raw)
        else:  # (the sensor is then aligned coarsely: say why, not only "coarse")
            log.warning(
                "point %s: its recording %s is missing: the sensor is aligned without the camera's trigger events",
                point.point_id,
                raw if raw is not None else "(none recorded)",
            )
    return validate_point(
        lines if len(lines) else None,
        record,
        triggers,
        frame,
        sensor.beam,
        sensor.sync,
        str(attrs.get("units", "px")),
        compare_without_events=point.state != "flapping",
    )


def _centrelines_path(
    run_dir: Path,
    point: PointResult,
    out: Path,
    centrelines_dir: str | Path | None,
    reconstruct: TrackingSetup | None,
    raw: Path | None,
) -> Path | None:
    if reconstruct is not None:
        if raw is None or not raw.exists():
            log.warning("point %s: its recording %s is missing: not reconstructed", point.point_id, raw)
            return None
        target = out / "centrelines" / f"{point.point_id}_centrelines.h5"
        target.parent.mkdir(parents=True, exist_ok=True)
        reconstruct_file(raw, target, reconstruct)
        return target
    if centrelines_dir is not None:
        base = Path(centrelines_dir)
        for name in (f"{point.point_id}_centrelines.h5", f"{point.point_id}.h5"):
            if (base / name).exists():
                return base / name
        return None
    return run_dir / point.centreline_file if point.centreline_file else None


def _relative(path: Path, run_dir: Path) -> str:
    try:
        return str(path.resolve().relative_to(run_dir.resolve()))
    except ValueError:
        return str(path.resolve())
