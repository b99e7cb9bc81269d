"""A point's sensor data beside its events and centrelines: ``points/<id>_sensor.h5``.

HDF5 layout (readable from MATLAB and Python)::

    /t_us            int64 (n,)  sample times, sensor clock, µs
    /value           float64 (n,) readings, sensor units, NaN = missing
    /trigger_t_us    int64 (m,)  trigger pulses on the sensor clock, µs
    /wall/t_us       int64 (k,)  sensor time of the newest sample of each bus message ...
    /wall/ns         int64 (k,)  ... and the wall time (ns) it arrived
    /camera_wall/t_us int64 (j,) camera time of centreline updates ...
    /camera_wall/ns  int64 (j,)  ... and the wall time (ns) of the packets they used
    attrs: sensor_id, units, clock, missing, config (JSON), flagtrack_version
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.errors import FormatError

_I64 = np.int64


def _ints() -> np.ndarray:
    return np.zeros(0, dtype=_I64)


@dataclass(frozen=True)
class SensorRecord:
    """What a point sensor gave during one recording.

    Attributes:
        sensor_id, units: as published.
        clock: ``sensor`` or ``host``.
        t_us, value: samples (sensor clock µs, sensor units, NaN = missing).
        trigger_t_us: trigger pulses on the sensor clock.
        missing: samples lost (NaN ones included).
        wall_t_us, wall_ns: (sensor time, arrival wall time) pairs, for a rough clock link.
        camera_t_us, camera_wall_ns: (camera time, wall time) pairs of the camera's data.
        config: the sensor config (beam, sync, driver), plain values.
    """

    sensor_id: str = ""
    units: str = ""
    clock: str = "sensor"
    t_us: np.ndarray = field(default_factory=_ints)
    value: np.ndarray = field(default_factory=lambda: np.zeros(0))
    trigger_t_us: np.ndarray = field(default_factory=_ints)
    missing: int = 0
    wall_t_us: np.ndarray = field(default_factory=_ints)
    wall_ns: np.ndarray = field(default_factory=_ints)
    camera_t_us: np.ndarray = field(default_factory=_ints)
    camera_wall_ns: np.ndarray = field(default_factory=_ints)
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def n_valid(self) -> int:
        """Samples with a reading."""
        return int(np.isfinite(self.value).sum())


_ARRAYS = {
    "t_us": "t_us",
    "value": "value",
    "trigger_t_us": "trigger_t_us",
    "wall_t_us": "wall/t_us",
    "wall_ns": "wall/ns",
    "camera_t_us": "camera_wall/t_us",
    "camera_wall_ns": "camera_wall/ns",
}


def write_sensor_record(path: str | Path, record: SensorRecord) -> Path:
    """Write ``record`` to ``path`` (HDF5, replaced if it exists)."""
    import h5py

    from flagtrack.daemon import __version__

    path = Path(path)
    with h5py.File(path, "w") as f:
        for name, where in _ARRAYS.items():
            f.create_dataset(where, data=np.asarray(getattr(record, name)))
        f.attrs.update(
            {
                "sensor_id": record.sensor_id,
                "units": record.units,
                "clock": record.clock,
                "missing": int(record.missing),
                "config": json.dumps(record.config),
                "flagtrack_version": __version__,
            }
        )
    return path


def read_sensor_record(path: str | Path) -> SensorRecord:
    """Read a file written by :func:`write_sensor_record`.

    Raises:
        FormatError: missing or unreadable file, or a missing dataset.
    """
    import h5py

    try:
        with h5py.File(path, "r") as f:
            arrays = {name: np.asarray(f[where][()]) for name, where in _ARRAYS.items()}
            attrs = dict(f.attrs)
    except (OSError, KeyError) as exc:
        raise FormatError(f"cannot read the sensor record: {exc}", path=str(path)) from exc
    try:
        config = json.loads(attrs.get("config", "{}"))
    except ValueError as exc:
        raise FormatError(f"bad config attribute: {exc}", path=str(path)) from exc
    return SensorRecord(
        str(attrs.get("sensor_id", "")),
        str(attrs.get("units", "")),
        str(attrs.get("clock", "sensor")),
        missing=int(attrs.get("missing", 0)),
        config=config,
        **arrays,
    )
