"""One row per input (or per sweep run) of a batch: ``batch.csv`` and ``batch.json``."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from flagtrack.drivers.atomic import atomic_open

CSV_NAME, JSON_NAME = "batch.csv", "batch.json"
COLUMNS = ("input", "events", "duration", "updates", "seconds", "worker", "status", "error", "output")
Status = Literal["done", "skipped", "failed"]


@dataclass(frozen=True)
class Row:
    """What a batch did with one input.

    Attributes:
        input: the recording (or sweep run folder), resolved.
        events: events in the recording (``events_in`` of the output); None when failed.
        duration: seconds of recording the centrelines span (last minus first update time, 0 for
            fewer than two updates); for a run, the sum over its points; None when failed.
        updates: centreline updates in the output (for a run, over its points); None when failed.
        seconds: wall time the worker spent on it (hashing, reconstructing, writing; checking only when
            skipped); for a run, the sum over its points and its validation.
        worker: ``host:pid`` of the process that did it (for a run, the one that validated it).
        status: ``done``, ``skipped`` (the output was up to date) or ``failed``.
        error: why it failed (names the file), else None.
        output: the centreline file (for a run, its ``validation.csv``); None when failed.
    """

    input: str
    events: int | None
    duration: float | None
    updates: int | None
    seconds: float
    worker: str
    status: Status
    error: str | None = None
    output: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The row as plain values (JSON)."""
        return dataclasses.asdict(self)


def failed_row(input_path: str | Path, error: str, *, seconds: float = 0.0, worker: str = "") -> Row:
    """A row for an input that failed (``error`` says why, naming the file)."""
    return Row(str(input_path), None, None, None, seconds, worker, "failed", error, None)


def count(rows: Sequence[Row]) -> dict[str, int]:
    """Rows per status: ``{"done": ..., "skipped": ..., "failed": ...}``."""
    return {status: sum(r.status == status for r in rows) for status in ("done", "skipped", "failed")}


def write_csv(rows: Sequence[Row], path: Path) -> Path:
    """Write ``rows`` as CSV with :data:`COLUMNS` (empty cells for None), atomically."""
    with atomic_open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(COLUMNS)
        for row in rows:
            values = row.as_dict()
            writer.writerow(["" if values[name] is None else _cell(values[name]) for name in COLUMNS])
    return path


def _cell(value: object) -> object:
    return repr(value) if isinstance(value, float) else value


def write_json(document: Mapping[str, Any], path: Path) -> Path:
    """Write ``document`` as JSON (non-finite numbers as null), atomically."""
    with atomic_open(path, "w") as handle:
        json.dump(_finite(document), handle, indent=1, allow_nan=False)
        handle.write("\n")
    return path


def _finite(value: Any) -> Any:
    """``value`` with NaN and infinities as None, tuples as lists, paths as strings (JSON has none of them)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "tolist"):  # NumPy scalars and arrays
        return _finite(value.tolist())
    return value
