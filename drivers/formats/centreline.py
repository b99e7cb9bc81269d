"""Centreline HDF5 files (the layout of docs/formats.md), readable from MATLAB and Python.

``/t`` (n_t,) s, ``/s`` (n_s,), ``/x`` ``/y`` (n_t, n_s), ``/joints/x`` ``/joints/y`` (n_t, N_j+1),
``/delta_rms`` (n_t,), ``/n_events`` (n_t,) int64, ``/lost`` (n_t,) uint8 (1: the flag was not found
in that update, its shape is not to be trusted; a file written before it reads as zeros), ``/stale``
(n_t,) uint8 (1: the shape rests on no recent evidence, remembered, not measured; a file written
before it reads as zeros), ``/shed`` (n_t,) float32 (the fraction of the camera's data since the
previous update that a live tracker shed for its latency budget; a file written before it reads as
zeros). Every dataset carries ``units`` and ``description`` attributes
(:mod:`.centreline_layout`); root attributes hold every processing parameter, ``units``,
``input_file``, the sensor size, ``format_version`` and ``flagtrack_version``. Files are written
incrementally (resizable datasets, flushed per append) so memory is bounded and a crash keeps what
was flushed.

Every centreline file flagtrack writes (``reconstruct``, ``up --centrelines``, the recorder's files)
goes through one :class:`CentrelineSink`: one shape check, one batching rule and one attribute rule
(:func:`centreline_attrs`), so each file says how it was made.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from flagtrack.daemon import __version__
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.atomic import PendingFile
from flagtrack.drivers.formats.centreline_layout import FORMAT, describe_datasets, hdf5_attrs, root_format_attrs

_PER_UPDATE = ("t", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events")
_MAX_PENDING_VALUES = 1 << 23
"""A sink also appends once its pending updates hold this many samples and joints (long centrelines)."""
_LAYOUT = ("t", "s", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events", "lost", "stale", "shed")


_SERIES = ("t", "x", "y", "joints/x", "joints/y", "delta_rms", "n_events", "lost", "stale", "shed")
"""The datasets that grow by one row per update."""


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
        try:
            self._file = h5py.File(self.path, "w")
        except OSError as exc:  # (h5py's text: its flags and internal names)
            why = os.strerror(exc.errno) if exc.errno else str(exc)
            raise FormatError(f"cannot create a file in {self.path.parent}: {why}", path=str(self.path)) from None
        n_s = len(s)
        self._file.create_dataset("s", data=np.asarray(s, dtype=np.float64))
        chunk_t = 256  # rows per chunk; the last chunk's unused rows take disk (1024: a 2 s point's file +40 %)
        self._file.create_dataset("t", (0,), maxshape=(None,), dtype="f8", chunks=(chunk_t,))
        for name, width in (("x", n_s), ("y", n_s), ("joints/x", n_joints + 1), ("joints/y", n_joints + 1)):
            self._file.create_dataset(name, (0, width), maxshape=(None, width), dtype="f8", chunks=(chunk_t, width))
        self._file.create_dataset("delta_rms", (0,), maxshape=(None,), dtype="f8", chunks=(chunk_t,))
        self._file.create_dataset("n_events", (0,), maxshape=(None,), dtype="i8", chunks=(chunk_t,))
        for name in ("lost", "stale"):
            self._file.create_dataset(name, (0,), maxshape=(None,), dtype="u1", chunks=(chunk_t,))
        self._file.create_dataset("shed", (0,), maxshape=(None,), dtype="f4", chunks=(chunk_t,))
        write_attrs(self._file, {"flagtrack_version": __version__, **attrs, **root_format_attrs(attrs)})
        # held open: a dataset object let go after each append closes its HDF5 handle then, and on a
        # full disk that close fails where nothing can catch it (a traceback per dataset per append)
        self._datasets = {name: self._file[name] for name in _SERIES}
        self.n_updates = 0
        self.describe()

    def describe(self) -> None:
        """Give every dataset its ``units`` and ``description`` (the table of :mod:`.centreline_layout`)."""
        describe_datasets(self._file, str(self._file.attrs.get("units", "")))

    def append(self, batch: CentrelineBatch) -> None:
        """Append ``batch`` (its ``s`` must match the file's) and flush."""
        n = len(batch)
        if n == 0:
            return
        columns = {
            "t": batch.t_s,
            "x": batch.x,
            "y": batch.y,
            "joints/x": batch.joints_x,
            "joints/y": batch.joints_y,
            "delta_rms": batch.delta_rms,
            "n_events": batch.n_events,
            "lost": batch.lost,
            "stale": batch.stale,
            "shed": batch.shed,
        }
        start = self.n_updates
        for name, values in columns.items():
            dataset = self._datasets[name]
            dataset.resize(start + n, axis=0)
            dataset[start:] = values
        self.n_updates += n
        self._file.flush()

    def set_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Add or replace root attributes (for values known only at the end)."""
        write_attrs(self._file, attrs)

    def close(self) -> None:
        """Describe the datasets, flush and close the file (idempotent)."""
        if self._file.id.valid:
            self.describe()
            self._file.flush()
            self._file.close()

    def __enter__(self) -> CentrelineWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_attrs(target: h5py.File | h5py.Group, attrs: Mapping[str, Any]) -> None:
    """Store attributes as :func:`~.centreline_layout.hdf5_attrs` says; a None removes the attribute
    (an unset value is absent, never the text ``null``)."""
    for name in (name for name, value in attrs.items() if value is None and name in target.attrs):
        del target.attrs[name]
    for name, value in hdf5_attrs(attrs).items():
        target.attrs[name] = value


def centreline_attrs(
    processing: Mapping[str, Any],
    *,
    units: str,
    input_file: str | None = None,
    calibration: Mapping[str, Any] | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """The root attributes every centreline file carries (``flagtrack_version`` is added by the writer).

    Args:
        processing: every processing parameter (``TrackingConfig.attrs()``), and the calibration's
            attributes if the composition root put them there.
        units: the length unit of ``/s``, ``/x`` ... (``px``, or ``m`` with a calibration).
        input_file: what the centrelines were tracked from (an event file, the recorder's ``.raw``);
            None keeps ``processing``'s ``input_file``, and a file without one says ``null``.
        calibration: the calibration's attributes (``flagtrack.calibration.calibration_attrs``), if any.
        extra: anything else (``input_format``, ``source``, ``events_in``, ``sensor_width_px`` ...).
    """
    attrs = {**processing, **(calibration or {}), **extra, "units": units}
    attrs["input_file"] = input_file if input_file is not None else processing.get("input_file")
    return attrs


class CentrelineShapeError(FormatError):
    """A batch whose samples or joints differ from the file's (another tracker setup): not written.

    Attributes:
        got: (n_s, N_j + 1) of the batch.
        want: (n_s, N_j + 1) of the file.
    """

    def __init__(self, got: tuple[int, int], want: tuple[int, int], *, path: str | None = None) -> None:
        self.got = got
        self.want = want
        super().__init__(
            f"a batch of {got[0]} samples and {got[1]} joints does not fit the file's {want[0]} "
            f"samples and {want[1]} joints: not written",
            path=path,
        )


class CentrelineSink:
    """Where a stream of centreline batches goes: one file, checked, batched, with its provenance.

    The file's samples ``s`` and joints (N_j + 1) are those of the first batch (or ``s`` and
    ``n_joints`` given here); a batch of another shape is refused with
    :class:`CentrelineShapeError` and nothing of it is written. The file is created at the first
    non-empty batch (its parent folder too), or at :meth:`close` when the shape is known but no
    update came (an empty series); a sink that never saw a batch and was given no shape leaves no file.

    Batches are held in memory and written in one HDF5 append (flushed to the OS) by :meth:`flush`,
    or by :meth:`add` when ``max_pending`` updates wait or ``flush_interval_s`` has passed since the
    last append; a caller whose loop also wakes without batches calls :meth:`flush_if_due`. A crash
    keeps what was appended.

    Use as a context manager (or call :meth:`close`). With ``atomic``, the file is written under a
    temporary name in the same folder and renamed onto ``path`` at a successful close; an exception
    leaving the ``with`` block (or :meth:`abort`) removes it, so ``path`` only ever holds a whole file.

    Args:
        path: the output file (overwritten).
        attrs: the provenance attributes (processing parameters, calibration, ``input_file`` ...);
            the file's root attributes are :func:`centreline_attrs` of them with the units.
        s: (n_s,) arc length of the samples, if known before the first batch.
        n_joints: number of chain links N_j, with ``s``.
        max_pending: updates held before an append (fewer when each holds many samples).
        flush_interval_s: append at least this often (on :meth:`add` and :meth:`flush_if_due`), or only
            by ``max_pending`` and :meth:`flush`.
        atomic: write to a temporary file, renamed onto ``path`` at a successful close.
    """

    def __init__(
        self,
        path: str | Path,
        attrs: Mapping[str, Any],
        *,
        s: np.ndarray | None = None,
        n_joints: int | None = None,
        max_pending: int = 8192,
        flush_interval_s: float | None = None,
        atomic: bool = False,
    ) -> None:
        if (s is None) != (n_joints is None):
            raise ValueError("give both s and n_joints, or neither")
        self.path = Path(path)
        self.max_pending = max_pending
        self.flush_interval_s = flush_interval_s
        self.atomic = atomic
        self._attrs = dict(attrs)
        self._units: str | None = None
        self._source: str | None = None
        self._s: np.ndarray | None = None
        self._shape: tuple[int, int] | None = None  # (n_s, N_j + 1) of the file
        if s is not None and n_joints is not None:
            self._s = np.asarray(s, dtype=np.float64)
            self._shape = (len(self._s), n_joints + 1)
        self._writer: CentrelineWriter | None = None
        self._tmp: PendingFile | None = None
        self._pending: list[CentrelineBatch] = []
        self.n_pending = 0
        self._last_flush = time.monotonic()
        self._closed = False

    @property
    def opened(self) -> bool:
        """Whether the file has been created (at ``path``, or at its temporary name when atomic)."""
        return self._writer is not None

    @property
    def n_updates(self) -> int:
        """Updates appended to the file so far (not counting those pending)."""
        return self._writer.n_updates if self._writer is not None else 0

    def add(self, batch: CentrelineBatch, *, units: str | None = None, source: str | None = None) -> None:
        """Queue ``batch``; append the pending batches if ``max_pending`` or ``flush_interval_s`` is reached.

        Args:
            batch: the updates.
            units: their length unit (e.g. the bus message's); the file's ``units`` attribute if this
                batch is the first to give one (over the ``units`` of ``attrs``).
            source: who produced them (the bus message's ``source``); the file's ``source`` likewise.

        Raises:
            CentrelineShapeError: the batch's samples or joints differ from the file's; nothing of it
                is queued.
        """
        if self._closed:
            raise ValueError(f"{self.path}: centreline sink is closed")
        shape = (len(batch.s), batch.joints_x.shape[1])
        if self._shape is None:
            self._shape, self._s = shape, np.asarray(batch.s, dtype=np.float64)
        elif shape != self._shape:
            raise CentrelineShapeError(shape, self._shape, path=str(self.path))
        if self._units is None:
            self._units = units
        if self._source is None:
            self._source = source
        if len(batch) == 0:
            return
        if self._writer is None:
            self._open()
        self._pending.append(batch)
        self.n_pending += len(batch)
        if (
            self.n_pending >= self.max_pending
            or self.n_pending * (self._shape[0] + self._shape[1]) > _MAX_PENDING_VALUES
        ):
            self.flush()
        else:
            self.flush_if_due()

    def flush_if_due(self) -> None:
        """Append the pending batches if ``flush_interval_s`` has passed since the last append."""
        if self.flush_interval_s is not None and time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Append the pending batches to the file in one append, flushed to the OS."""
        self._last_flush = time.monotonic()
        if not self._pending:
            return
        assert self._writer is not None  # opened by the first non-empty batch
        batch = self._pending[0] if len(self._pending) == 1 else CentrelineBatch.concatenate(self._pending)
        self._pending, self.n_pending = [], 0
        self._writer.append(batch)

    def set_attrs(self, attrs: Mapping[str, Any]) -> None:
        """Add or replace root attributes (for values known only at the end: ``events_in`` ...)."""
        if self._closed:
            raise ValueError(f"{self.path}: centreline sink is closed")
        self._attrs.update(attrs)
        if self._writer is not None:
            self._writer.set_attrs(attrs)

    def close(self) -> None:
        """Append what is pending and close the file (renamed onto ``path`` when atomic). Idempotent.

        When atomic and this fails, the temporary file is removed and ``path`` is left as it was.
        """
        if self._closed:
            return
        self._closed = True
        try:
            try:
                if self._writer is None and self._shape is not None:
                    self._open()  # the shape is known but no update came: an empty series
                self.flush()
            finally:
                if self._writer is not None:
                    self._writer.close()
            if self._tmp is not None:
                self._tmp.commit()
                self._tmp = None
        except BaseException:
            self._discard_tmp()
            raise

    def abort(self) -> None:
        """Close without appending what is pending; when atomic, remove the temporary file (nothing at ``path``)."""
        self._closed = True
        self._pending, self.n_pending = [], 0
        try:
            if self._writer is not None:
                self._writer.close()
        finally:
            self._discard_tmp()

    def __enter__(self) -> CentrelineSink:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        if exc_type is not None and self.atomic:
            self.abort()
        else:
            self.close()

    def _open(self) -> None:
        assert self._s is not None and self._shape is not None
        units = self._units if self._units is not None else self._attrs.get("units")
        if units is None:
            raise ValueError(f"{self.path}: the centrelines' units are not known (give them in attrs or to add)")
        extra: dict[str, Any] = {"source": self._source} if self._source is not None else {}
        attrs = centreline_attrs(self._attrs, units=units, **extra)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        target = self.path
        if self.atomic:  # a name of its own in the same folder (a rename within one file system)
            self._tmp = PendingFile(self.path)
            target = self._tmp.tmp
        try:
            self._writer = CentrelineWriter(target, self._s, self._shape[1] - 1, attrs)
        except BaseException:
            self._discard_tmp()
            raise
        self._last_flush = time.monotonic()

    def _discard_tmp(self) -> None:
        if self._tmp is not None:
            self._tmp.discard()
            self._tmp = None


def write_centrelines(path: str | Path, batch: CentrelineBatch, attrs: Mapping[str, Any]) -> None:
    """Write a whole series to ``path`` in one go."""
    with CentrelineWriter(path, batch.s, batch.joints_x.shape[1] - 1, attrs) as writer:
        writer.append(batch)


def is_centreline_file(path: str | Path) -> bool | None:
    """Whether ``path`` is a flagtrack centreline file (an earlier output that may be replaced); None
    when it cannot tell: an HDF5 file it cannot open (cut by a forced exit, in use), or no permission."""
    try:
        with open(path, "rb") as file:
            if file.read(8) != b"\x89HDF\r\n\x1a\n":
                return False
        with h5py.File(path, "r") as f:
            return _decode_attr(f.attrs.get("format", "")) == FORMAT or all(name in f for name in ("t", "s", "joints"))
    except (OSError, ValueError):
        return None


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
                t_s=f["t"][()],
                s=f["s"][()],
                x=f["x"][()],
                y=f["y"][()],
                joints_x=f["joints/x"][()],
                joints_y=f["joints/y"][()],
                delta_rms=f["delta_rms"][()],
                n_events=f["n_events"][()],
                lost=f["lost"][()] if "lost" in f else np.zeros(len(f["t"]), np.uint8),
                stale=f["stale"][()] if "stale" in f else np.zeros(len(f["t"]), np.uint8),
                shed=f["shed"][()] if "shed" in f else np.zeros(len(f["t"]), np.float32),
            )
            attrs = {name: _decode_attr(value) for name, value in f.attrs.items()}
    except OSError as exc:
        raise FormatError(f"cannot open as HDF5: {exc}", path=str(path)) from exc
    except ValueError as exc:  # datasets of disagreeing shapes (another program's file, a damaged one)
        raise FormatError(f"not a flagtrack centreline file: {exc}", path=str(path)) from None
    return batch, attrs


#: What a ground truth must hold: times, arc lengths and centrelines (a truth from another simulator
#: may have nothing else); the other datasets of the layout are read when present.
TRUTH_REQUIRED = ("t", "s", "x", "y")


def read_truth(path: str | Path) -> tuple[CentrelineBatch, dict[str, Any], tuple[str, ...]]:
    """Read a ground-truth centreline file that may hold only ``/t``, ``/s``, ``/x``, ``/y``.

    The datasets of the layout it lacks stand in as NaN (``/joints/*``: no column, ``/delta_rms``:
    NaN, ``/n_events``: 0); the third value says which datasets were read, so a caller reports
    what it could not compute rather than compute it from the stand-ins.

    Returns:
        (series, root attributes, names of the datasets read in layout order: ``t``, ``s``, ``x``, ``y``,
        then those of ``joints/x`` and ``joints/y`` (both or neither), ``delta_rms``, ``n_events`` it has).

    Raises:
        FormatError: the file is missing or not HDF5, lacks one of :data:`TRUTH_REQUIRED` (named), or
            its shapes disagree.
    """
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            names = tuple(name for name in _LAYOUT if isinstance(f.get(name), h5py.Dataset))
            for name in TRUTH_REQUIRED:
                if name not in names:
                    needs = ", ".join(f"/{n}" for n in TRUTH_REQUIRED)
                    raise FormatError(f"ground truth has no /{name} dataset (a truth needs {needs})", path=str(path))
            data = {name: f[name][()] for name in names}
            attrs = {name: _decode_attr(value) for name, value in f.attrs.items()}
    except OSError as exc:
        raise FormatError(f"cannot open as HDF5: {exc}", path=str(path)) from exc
    t_s = np.asarray(data["t"], dtype=np.float64)
    n_t = len(t_s)
    joints = "joints/x" in data and "joints/y" in data
    try:
        batch = CentrelineBatch(
            t_s=t_s,
            s=np.asarray(data["s"], dtype=np.float64),
            x=np.asarray(data["x"], dtype=np.float64),
            y=np.asarray(data["y"], dtype=np.float64),
            joints_x=np.asarray(data["joints/x"], dtype=np.float64) if joints else np.empty((n_t, 0)),
            joints_y=np.asarray(data["joints/y"], dtype=np.float64) if joints else np.empty((n_t, 0)),
            delta_rms=np.asarray(data.get("delta_rms", np.full(n_t, np.nan)), dtype=np.float64),
            n_events=np.asarray(data.get("n_events", np.zeros(n_t)), dtype=np.int64),
            lost=np.asarray(data.get("lost", np.zeros(n_t)), dtype=np.uint8),
            stale=np.asarray(data.get("stale", np.zeros(n_t)), dtype=np.uint8),
            shed=np.asarray(data.get("shed", np.zeros(n_t)), dtype=np.float32),
        )
    except ValueError as exc:
        raise FormatError(f"ground truth: {exc}", path=str(path)) from exc
    if n_t == 0 or not np.all(np.diff(t_s) > 0):
        raise FormatError("ground truth: /t is empty or not increasing", path=str(path))
    return batch, attrs, tuple(name for name in names if joints or not name.startswith("joints/"))


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
