"""What every dataset and root attribute of a centreline file means: one table, written into each file.

Every dataset gets a ``units`` and a ``description`` attribute from :data:`DATASETS` (``LENGTH`` stands
for the file's length unit, its root ``units``: ``px``, or the calibration's plane unit), so a reader
with nothing but an HDF5 library (MATLAB's ``h5readatt``, h5py) finds what each array is. A dataset
added to the layout gets its entry here; ``tests/unit/test_centreline_layout.py`` fails on a written
dataset without both attributes. The layout is described in docs/formats.md.

Root attributes follow :func:`hdf5_attrs`: an unset value (None) is absent, a boolean is 0 or 1 (an
integer, not an HDF5 enum), lists of numbers are numeric vectors, other lists and mappings JSON text.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np

FORMAT = "flagtrack-centrelines"
FORMAT_VERSION = 2
"""2: ``units``/``description`` on every dataset, ``format``/``format_version`` and the sensor size at the
root, no ``'null'`` strings, booleans as 0/1. A file without ``format_version`` is version 1 (read alike)."""

LENGTH = "<length>"
"""Stands for the file's length unit in :data:`DATASETS` (the root attribute ``units``)."""


@dataclass(frozen=True)
class DatasetSpec:
    """One dataset of the layout: its path, shape (C order, as h5py reads it), type, unit, meaning."""

    name: str
    shape: str
    dtype: str
    units: str
    description: str


DATASETS: tuple[DatasetSpec, ...] = (
    DatasetSpec("t", "(n_t,)", "float64", "s",
                "update time: the centre of the update's event window, on the recording's clock (event t / 1e6)"),
    DatasetSpec("s", "(n_s,)", "float64", LENGTH, "arc length of the centreline samples from the root, 0 to L"),
    DatasetSpec("x", "(n_t, n_s)", "float64", LENGTH,
                "x of the smoothed centreline at each arc length s, one row per update (MATLAB's h5read "
                "returns the transpose, (n_s, n_t))"),
    DatasetSpec("y", "(n_t, n_s)", "float64", LENGTH,
                "y of the smoothed centreline at each arc length s, one row per update (MATLAB's h5read "
                "returns the transpose, (n_s, n_t))"),
    DatasetSpec("joints/x", "(n_t, N_j+1)", "float64", LENGTH,
                "x of the chain's joints, root first, tip last, one row per update (MATLAB: the transpose)"),
    DatasetSpec("joints/y", "(n_t, N_j+1)", "float64", LENGTH,
                "y of the chain's joints, root first, tip last, one row per update (MATLAB: the transpose)"),
    DatasetSpec("delta_rms", "(n_t,)", "float64", LENGTH,
                "Delta_RMS, the event-cloud distance: RMS distance of the update's events to its smoothed "
                "centreline (the paper's Delta_RMS; not the tip error delta); NaN for an update without events"),
    DatasetSpec("n_events", "(n_t,)", "int64", "1", "number of events the update used"),
    DatasetSpec("lost", "(n_t,)", "uint8", "1",
                "1 where the flag was not found in the update (its shape is not to be trusted), else 0"),
    DatasetSpec("stale", "(n_t,)", "uint8", "1",
                "1 where the update rests on no events newer than tracker.lost.stale_after_s, else 0"),
    DatasetSpec("shed", "(n_t,)", "float32", "1",
                "fraction of the camera time since the previous update that the live tracker skipped to stay within tracker.max_lag_ms"),
)  # fmt: skip

#: Root attributes a reader needs besides the processing parameters (docs/formats.md lists them all).
ROOT_ATTRIBUTES: dict[str, str] = {
    "format": f"'{FORMAT}'",
    "format_version": "layout version (integer); absent in files written before it (version 1)",
    "units": "length unit of /s, /x, /y, /joints/*, /delta_rms and of length and root: px, or m with a calibration",
    "length": "the flag's length L, in units",
    "root": "the flag's root (x, y), in units",
    "direction_deg": "the flag's rest direction, degrees from +x towards +y",
    "sensor_width_px": "the camera sensor's width, pixels (absent where not known)",
    "sensor_height_px": "the camera sensor's height, pixels (absent where not known)",
    "calibration_units": "the calibration's plane unit (with a calibration only)",
    "input_file": "what the centrelines were tracked from (absent where not known)",
    "flagtrack_version": "the flagtrack that wrote the file",
}


def dataset_spec(name: str) -> DatasetSpec | None:
    """The entry of :data:`DATASETS` for the dataset ``name`` (``joints/x``; a leading ``/`` is ignored)."""
    name = name.lstrip("/")
    return next((spec for spec in DATASETS if spec.name == name), None)


def describe_datasets(file: h5py.File, length_units: str) -> None:
    """Give every dataset of ``file`` that :data:`DATASETS` knows its ``units`` and ``description``."""

    def visit(name: str, node: Any) -> None:
        spec = dataset_spec(name)
        if isinstance(node, h5py.Dataset) and spec is not None:
            node.attrs["units"] = length_units if spec.units == LENGTH else spec.units
            node.attrs["description"] = spec.description

    file.visititems(visit)


def root_format_attrs(attrs: Mapping[str, Any]) -> dict[str, Any]:
    """The root attributes a writer adds to ``attrs``: ``format``, ``format_version`` and, for a file
    made with a calibration (``calibration_*`` attributes), ``calibration_units`` (the file's ``units``)."""
    extra: dict[str, Any] = {"format": FORMAT, "format_version": FORMAT_VERSION}
    calibrated = any(name.startswith("calibration_") for name in attrs)
    if calibrated and "calibration_units" not in attrs and attrs.get("units") is not None:
        extra["calibration_units"] = attrs["units"]
    return extra


def hdf5_attrs(attrs: Mapping[str, Any]) -> dict[str, Any]:
    """``attrs`` as HDF5 root attributes: None -> absent (left out), bool -> 0/1, a list of numbers -> a
    vector, other lists/tuples/mappings -> JSON text, the rest as given."""
    import json

    out: dict[str, Any] = {}
    for name, value in attrs.items():
        if value is None:
            continue
        if isinstance(value, bool | np.bool_):
            out[name] = int(value)
        elif isinstance(value, dict | list | tuple) and not _is_numeric_sequence(value):
            out[name] = json.dumps(value)
        else:
            out[name] = value
    return out


def _is_numeric_sequence(value: Any) -> bool:
    return (
        isinstance(value, list | tuple)
        and len(value) > 0
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    )
