"""The point-sensor check of one sweep point: store the samples, synchronise, compare, draw.

Called by the supervisor at the end of each point. It never fails the point: any problem (no
samples, no raw file, a broken figure) ends up in ``sensor_status`` and the point is recorded.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.events import empty_triggers
from flagtrack.daemon.services.supervisor.monitor import Collection
from flagtrack.daemon.typed_yaml import to_mapping
from flagtrack.daemon.validation.collect import raw_triggers, record_from_messages
from flagtrack.daemon.validation.figures import plot_point
from flagtrack.daemon.validation.point import FlagFrame, validate_point
from flagtrack.drivers.sensor.record import write_sensor_record
from flagtrack.drivers.sensor.setup import SensorConfig

log = logging.getLogger(__name__)


def sensor_paths(base: Path) -> tuple[Path, Path]:
    """The sensor record and figure of the point whose files start with ``base``."""
    return base.with_name(base.name + "_sensor.h5"), base.with_name(base.name + "_sensor.png")


def check_point(
    base: Path,
    run_dir: Path,
    collection: Collection,
    raw: Path,
    frame: FlagFrame,
    cfg: SensorConfig,
    state: str,
    title: str = "",
) -> dict[str, Any]:
    """Write ``<base>_sensor.h5`` and ``<base>_sensor.png``; return the point's sensor fields.

    Args:
        base: the point's file prefix (``RUN/points/<id>``).
        run_dir: the run folder (stored paths are relative to it).
        collection: what the monitor gathered during the recording.
        raw: the point's raw event file (its trigger events synchronise the clocks).
        frame: the flag's rest frame and length (tracker units).
        cfg: the ``sensor:`` section.
        state: the flag's state; for a flapping flag, updates made without events (lost camera
            data) are not compared.
        title: figure title.
    """
    record_path, figure_path = sensor_paths(base)
    fields: dict[str, Any] = {}
    try:
        record = record_from_messages(collection.sensor, collection.camera_wall, to_mapping(cfg))
        write_sensor_record(record_path, record)
        fields["sensor_file"] = str(record_path.relative_to(run_dir))
        triggers = empty_triggers()
        if cfg.sync.mode in ("auto", "trigger") and raw.exists() and len(record.trigger_t_us):
            triggers = raw_triggers(raw)
        lines = CentrelineBatch.concatenate(collection.batches) if collection.batches else None
        validation = validate_point(
            lines,
            record,
            triggers,
            frame,
            cfg.beam,
            cfg.sync,
            collection.units,
            compare_without_events=state != "flapping",
        )
        fields.update(validation.fields())
        plot_point(validation, figure_path, title)
        fields["sensor_figure"] = str(figure_path.relative_to(run_dir))
        _log_check(cfg.id, validation, fields["sensor_error_rms_over_l"])
    except Exception as exc:  # noqa: BLE001 - the sensor never fails a point: say what went wrong instead
        log.error("supervisor: sensor check of %s failed: %s", base.name, exc)
        fields["sensor_status"] = f"error: {type(exc).__name__}: {exc}"
    return fields


def _log_check(sensor_id: str, validation: Any, error_rms_over_l: float) -> None:
    sync = validation.sync
    log.info(
        "supervisor: sensor %s: %s, e/L RMS %.2f %% of L, sync %s %.1f ± %.1f us",
        sensor_id,
        validation.status,
        100 * error_rms_over_l,
        sync.method,
        sync.offset_us,
        sync.uncertainty_us,
    )
