"""Centreline HDF5 files (DESIGN.md layout), readable from MATLAB and Python.

``/t`` (n_t,) s, ``/s`` (n_s,), ``/x`` ``/y`` (n_t, n_s), ``/joints/x`` ``/joints/y`` (n_t, N_j+1),
``/delta_rms`` (n_t,), ``/n_events`` (n_t,) int64; root attributes hold every processing
parameter, ``units``, ``input_file`` and ``flagtrack_version``. Files are written incrementally
(resizable datasets, flushed per append) so memory is bounded and a crash keeps what was flushed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from flagtrack.daemon import __version__
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import FormatError

_PER_UPDATE = ("t", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events")


class CentrelineWriter:
    """Append centreline batches to an HDF5 file; use as a context manager.

    Args:
        path: output file (overwritten).
        s: (n_s,) arc length of the samples.
        n_joints: number of chain links N_j (the joints datasets have N_j + 1 columns).
        attrs: processing parameters and provenance stored as root attributes; must include
            ``units``. Values that HDF5 cannot store natively are stored as JSON strings.
    """

    def __init__(self, path: str | Path, s: np.ndarray, n_joints: int, attrs: Mapping[str, Any]) -> None:
        self.path = Path(path)
        self._file = h5py.File(self.path, "w")
        n_s = len(s)
        self._file.create_dataset("s", data=np.asarray(s, dtype=np.float64))
        chunk_t = 1024
        self._file.create_dataset("t", (0,), maxshape=(None,), dtype="f8", chunks=(chunk_t,))
        for name, width in (("x", n_s), ("y", n_s), ("joints/x", n_joints + 1), ("joints/y", n_joints + 1)):
            self._file.create_dataset(name, (0, width), maxshape=(None, width), dtype="f8", chunks=(chunk_t, width))
        self._file.create_dataset("delta_rms", (0,), maxshape=(None,), dtype="f8", chunks=(chunk_t,))
        self._file.create_dataset("n_events", (0,), maxshape=(None,), dtype="i8", chunks=(chunk_t,))
        write_attrs(self._file, {"flagtrack_version": __version__, **attrs})
        self.n_updates = 0

    def append(self, batch: CentrelineBatch) -> None:
        """Append ``batch`` (its ``s`` must match the file's) and flush."""
        n = len(batch)
        if n == 0:
            return
        columns = {
            "t": batch.t_s, "x": batch.x, "y": batch.y, "joints/x": batch.joints_x,
            "joints/y": batch.joints_y, "delta_rms": batch.delta_rms, "n_events": batch.n_events,
        }
        start = self.n_updates
        for name, values in columns.items():
            dataset = self._file[name]
            dataset.resize(start + n, axis=0)
            dataset[start:] = values
        self.n_updates += n
        self._file.flush()

    def set_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Add or replace root attributes (for values known only at the end)."""
        write_attrs(self._file, attrs)

    def close(self) -> None:
        """Flush and close the file (idempotent)."""
        if self._file.id.valid:
            self._file.flush()
            self._file.close()

    def __enter__(self) -> CentrelineWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_attrs(target: h5py.File | h5py.Group, attrs: Mapping[str, Any]) -> None:
    """Store attributes; lists, dicts and None are stored as JSON strings."""
    for name, value in attrs.items():
        if value is None or isinstance(value, dict | list | tuple) and not _is_numeric_sequence(value):
            target.attrs[name] = json.dumps(value)
        else:
            target.attrs[name] = value


def _is_numeric_sequence(value: Any) -> bool:
    return isinstance(value, list | tuple) and len(value) > 0 and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    )


def write_centrelines(path: str | Path, batch: CentrelineBatch, attrs: Mapping[str, Any]) -> None:
    """Write a whole series to ``path`` in one go."""
    with CentrelineWriter(path, batch.s, batch.joints_x.shape[1] - 1, attrs) as writer:
        writer.append(batch)


def read_centrelines(path: str | Path) -> tuple[CentrelineBatch, dict[str, Any]]:
    """Read a centreline file; return the series and its root attributes.

    Raises:
        FormatError: the file is missing, not HDF5, or lacks a dataset of the layout.
    """
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            missing = [name for name in ("s", *_PER_UPDATE) if name not in f]
            if missing:
                raise FormatError(f"not a flagtrack centreline file: missing /{missing[0]}", path=str(path))
            batch = CentrelineBatch(
                t_s=f["t"][()], s=f["s"][()], x=f["x"][()], y=f["y"][()],
                joints_x=f["joints/x"][()], joints_y=f["joints/y"][()],
                delta_rms=f["delta_rms"][()], n_events=f["n_events"][()],
            )
            attrs = {name: _decode_attr(value) for name, value in f.attrs.items()}
    except OSError as exc:
        raise FormatError(f"cannot open as HDF5: {exc}", path=str(path)) from exc
    return batch, attrs


def _decode_attr(value: Any) -> Any:
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, str) and value[:1] in "[{n":
        try:
            return json.loads(value)
        except ValueError:
            return value
    if isinstance(value, np.generic):
        return value.item()
    return value
