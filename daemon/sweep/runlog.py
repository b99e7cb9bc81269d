"""The run log of a sweep: one folder per run, an append-only JSON-lines file ``run.jsonl``.

Records (one JSON object per line, each with ``type`` and the format version ``v``):

- ``start``: run id, flagtrack version, the run's config, the planned points, and the command
  line that made it (``command``; absent from runs made before it was stored);
- ``resume``: appended when an interrupted run is resumed, with the points already done (and the
  command line);
- ``point``: one per measured point: id, branch, speed, state, metrics, pointers to the raw and
  centreline files (relative to the run folder), status ``done``, ``failed`` or ``lossy`` (with its
  ``reason``; only ``done`` counts as finished, the others are measured again on resume);
- ``stop``: reason (``finished``, ``SIGTERM``, an error), appended on any orderly end.

A 1 MiB ``.reserve`` file in the run folder is given up when the disk is full, so the last point
and stop records still fit. Every line is written, flushed and fsync'ed before the writer returns, so after a power loss the
file holds every finished record and at most one torn last line, which the reader ignores (and
:meth:`RunLog.resume` cuts off before appending). NaN metrics are written as ``null``.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import logging
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from flagtrack.daemon import __version__
from flagtrack.daemon.errors import ConfigError, FormatError
from flagtrack.daemon.security.names import identifier_problem
from flagtrack.daemon.sweep.plan import Point, SweepConfig, plan_points
from flagtrack.daemon.sweep.quantities import POINT_ALIASES
from flagtrack.daemon.typed_yaml import from_mapping, to_mapping
from flagtrack.drivers.reserve import DiskReserve

log = logging.getLogger(__name__)

RUN_LOG = "run.jsonl"
LOG_VERSION = 1
POINTS_DIR = "points"
RESERVE = ".reserve"
RUN_LOG_RESERVE_BYTES = 1 << 20
"""Disk held in each run folder so the point and stop records still fit when the disk fills up."""
_BLANK = b" \t\r\n\x00"


@dataclass(frozen=True)
class PointResult:
    """What one point measured (the ``point`` record; also a row of the summary CSV).

    Attributes:
        point_id, index, branch: as planned (:class:`~flagtrack.daemon.sweep.plan.Point`).
        speed_mps: the set-point, m/s.
        status: ``done`` (counts as finished on resume), ``failed`` (the tunnel went silent, faulted
            or left its tolerance, or an action failed) or ``lossy`` (the recording lost packets).
        state: flag state over the recording (``still``, ``flapping``, ``unknown``).
        speed_readback_mps: mean tunnel readback during the recording, m/s.
        amplitude_over_l: tip amplitude A/L, half the peak-to-peak of the tip's lateral displacement
            over the recording, over L; amplitude_std_over_l: its standard deviation cycle by cycle.
        frequency_hz: flapping frequency, Hz.
        twi: travelling-wave index.
        cloud_distance_mean_over_l: time mean of the event-cloud distance Delta_RMS / L over the
            point's updates (``delta_rms_over_l`` in records written before; the paper's Delta_RMS,
            not the tip error).
        event_rate_mev_s: mean event rate, millions of events per second.
        raw_bytes: size of the raw event file, bytes.
        raw_file, centreline_file: paths relative to the run folder, or ``None``.
        t_start_unix, t_stop_unix: recording start and stop, Unix time s.
        error: what went wrong, for a failed point.
        cloud_distance_std_over_l: standard deviation of Delta_RMS / L over the updates
            (``delta_rms_std_over_l`` before).
        sensor_status: the point-sensor comparison: ``ok``, or why there is none (``None``: no sensor).
        sensor_error_rms_over_l, sensor_error_max_over_l: RMS and maximum of |e| / L, e = camera - sensor
            lateral displacement at the sensor's x.
        sensor_error_mean_over_l, sensor_error_std_over_l: time mean and std of |e| / L (paper fig. 5g).
        sensor_sync: clock sync used (``trigger``, ``xcorr``, ``coarse``, ``none``).
        sensor_offset_us, sensor_offset_unc_us, sensor_drift_ppm: sensor minus camera clock, its
            uncertainty, and the sensor clock's drift.
        sensor_xcorr_offset_us, sensor_xcorr_unc_us: the cross-correlation estimate (also holds the
            reconstruction's delay).
        sensor_samples, sensor_missing, sensor_compared: samples received, lost, and compared (a sample
            is compared when the reconstruction has updates around it).
        sensor_file, sensor_figure: the point's sensor record and figure, relative to the run folder.
        actions: how the point's actions went (``command ok; pause ok``), ``None`` without actions.
        lost_fraction: fraction of the point's updates that did not find the flag (``/lost``).
        suspect: ``lost_fraction`` (or, for a flapping point, ``stale_fraction``) is above the
            supervisor's ``suspect_lost_fraction``: the point's numbers may be those of something
            else than the flag, or of a shape the tracker only remembered.
        reason: why the point is ``failed`` or ``lossy`` (one line), ``None`` for a good point.
        shed_fraction: share of the point's camera time the live tracker shed to keep within its
            latency budget (``/shed``: its numbers rest on the rest; 0 when it tracked everything).
        stale_fraction: fraction of the point's updates whose shape rests on no recent events
            (``/stale``: remembered, not measured). A still flag gives few events, so a still point
            is not suspect for it (its A/L of 0 stands).
        chain_reach: where the flag's events ended along the live chain over the point's first
            events, a fraction of L (1: at its tip; NaN when not judged: a still flag, no recording
            here). Off 1 by more than 3 %, the chain's length is not the flag's and the point is
            suspect (docs/tracking.md).
    """

    point_id: str
    index: int
    branch: str
    speed_mps: float
    status: Literal["done", "failed", "lossy"] = "done"
    state: str = "unknown"
    speed_readback_mps: float = math.nan
    amplitude_over_l: float = math.nan
    amplitude_std_over_l: float = math.nan
    frequency_hz: float = math.nan
    twi: float = math.nan
    cloud_distance_mean_over_l: float = math.nan
    event_rate_mev_s: float = math.nan
    raw_bytes: int = 0
    raw_file: str | None = None
    centreline_file: str | None = None
    t_start_unix: float = math.nan
    t_stop_unix: float = math.nan
    error: str | None = None
    cloud_distance_std_over_l: float = math.nan
    sensor_status: str | None = None
    sensor_error_rms_over_l: float = math.nan
    sensor_error_max_over_l: float = math.nan
    sensor_error_mean_over_l: float = math.nan
    sensor_error_std_over_l: float = math.nan
    sensor_sync: str | None = None
    sensor_offset_us: float = math.nan
    sensor_offset_unc_us: float = math.nan
    sensor_drift_ppm: float = math.nan
    sensor_xcorr_offset_us: float = math.nan
    sensor_xcorr_unc_us: float = math.nan
    sensor_samples: int = 0
    sensor_missing: int = 0
    sensor_compared: int = 0
    sensor_file: str | None = None
    sensor_figure: str | None = None
    actions: str | None = None
    lost_fraction: float = math.nan
    suspect: bool = False
    reason: str | None = None
    shed_fraction: float = math.nan
    stale_fraction: float = math.nan
    chain_reach: float = math.nan

    @classmethod
    def planned(cls, point: Point, **values: Any) -> PointResult:
        """A result for ``point`` with the given metric ``values``."""
        return cls(point.point_id, point.index, point.branch.value, point.speed_mps, **values)


_FLOAT_FIELDS = {f.name for f in dataclasses.fields(PointResult) if f.type in ("float", float)}


def point_record(result: PointResult) -> dict[str, Any]:
    """A point as JSON: its fields (``None`` for a NaN), then the old keys of
    :data:`~flagtrack.daemon.sweep.quantities.POINT_ALIASES` with the same values."""
    record = {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in dataclasses.asdict(result).items()
    }
    return {**record, **{old: record[new] for old, new in POINT_ALIASES.items()}}


def point_paths(point_id: str) -> tuple[str, str]:
    """Raw and centreline file paths of a point, relative to the run folder."""
    return f"{POINTS_DIR}/{point_id}.raw", f"{POINTS_DIR}/{point_id}_centrelines.h5"  # as the recorder names them


@dataclass(frozen=True)
class RunRecord:
    """Everything a run log holds.

    Attributes:
        run_dir: the run folder.
        start: the start record.
        points: every point record, in file order (a point redone after a failure appears twice).
        resumes: the resume records.
        stop: the last stop record, or ``None`` (running, or killed).
        torn_tail: the last line was incomplete (power loss) and was ignored.
        valid_bytes: length of the file up to the last complete record.
    """

    run_dir: Path
    start: dict[str, Any]
    points: tuple[PointResult, ...]
    resumes: tuple[dict[str, Any], ...]
    stop: dict[str, Any] | None
    torn_tail: bool
    valid_bytes: int

    @property
    def planned_ids(self) -> list[str]:
        """Point ids of the plan stored in the start record."""
        return [p["point_id"] for p in self.start.get("plan", [])]

    def latest_points(self) -> dict[str, PointResult]:
        """The last record of each point, by point id, in plan order."""
        latest = {p.point_id: p for p in self.points}
        order = {pid: i for i, pid in enumerate(self.planned_ids)}
        return dict(sorted(latest.items(), key=lambda item: (order.get(item[0], len(order)), item[1].index)))


def read_run(run_dir: str | Path) -> RunRecord:
    """Read ``run_dir/run.jsonl``; a torn last line is ignored.

    Raises:
        FormatError: missing file, a malformed record before the last line, an unknown version,
            or a first record that is not ``start`` (the error names the file and byte offset).
    """
    run_dir = Path(run_dir)
    path = run_dir / RUN_LOG
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FormatError(f"cannot read the run log: {exc.strerror}", path=str(path)) from exc
    records: list[tuple[int, dict[str, Any]]] = []
    offset, torn = 0, False
    while offset < len(data):
        if not data[offset:].strip(_BLANK):  # a tail of NUL bytes (a crash during a write)
            torn = True
            break
        end = data.find(b"\n", offset)
        line = data[offset:] if end < 0 else data[offset:end]
        try:
            record = _decode(line, end < 0)
        except ValueError as exc:
            if end < 0 or not data[end + 1 :].strip(_BLANK):
                torn = True
                log.warning("%s: ignoring a torn last record at byte %d (%s)", path, offset, exc)
                break
            raise FormatError(f"malformed record: {exc}", path=str(path), offset=offset) from exc
        records.append((offset, record))
        offset = end + 1
    return _assemble(run_dir, path, records, torn, offset)


def _decode(line: bytes, last: bool) -> dict[str, Any]:
    if last:
        raise ValueError("no end of line")
    record = json.loads(line)
    if not isinstance(record, dict) or "type" not in record:
        raise ValueError("not a record object")
    return record


def _assemble(
    run_dir: Path, path: Path, records: list[tuple[int, dict[str, Any]]], torn: bool, valid: int
) -> RunRecord:
    if not records or records[0][1]["type"] != "start":
        raise FormatError("the run log does not begin with a start record", path=str(path), offset=0)
    points, resumes, stop = [], [], None
    for offset, record in records:
        if record.get("v") != LOG_VERSION:
            raise FormatError(f"unknown run-log version {record.get('v')!r}", path=str(path), offset=offset)
        kind = record["type"]
        if kind == "point":
            points.append(_point_from_json(record, path, offset))
        elif kind == "resume":
            resumes.append(record)
        elif kind == "stop":
            stop = record
        elif kind != "start" or offset != 0:
            raise FormatError(f"unexpected record type {kind!r}", path=str(path), offset=offset)
    return RunRecord(run_dir, records[0][1], tuple(points), tuple(resumes), stop, torn, valid)


def _point_from_json(record: dict[str, Any], path: Path, offset: int) -> PointResult:
    names = {f.name for f in dataclasses.fields(PointResult)}
    record = {**{new: record[old] for old, new in POINT_ALIASES.items() if old in record}, **record}
    values: dict[str, Any] = {  # JSON values: PointResult(**values) below says which field is wrong
        k: (math.nan if v is None and k in _FLOAT_FIELDS else v) for k, v in record.items() if k in names
    }
    problem = identifier_problem(values.get("point_id"), "point_id")  # it names files (validate, resume)
    for name in ("raw_file", "centreline_file"):  # paths inside the run folder
        file = values.get(name)
        if problem is None and file is not None and (not isinstance(file, str) or not _inside(file)):
            problem = f"{name} {str(file)[:80]!r} is not a path inside the run folder"
    if problem is not None:
        raise FormatError(f"point record: {problem}", path=str(path), offset=offset)
    try:
        return PointResult(**values)
    except TypeError as exc:
        raise FormatError(f"point record: {exc}", path=str(path), offset=offset) from exc


def _inside(relative: str) -> bool:
    parts = Path(relative).parts
    return bool(parts) and not Path(relative).is_absolute() and ".." not in parts and not relative.startswith("~")


def stored_sweep(record: RunRecord, section: str = "sweep") -> SweepConfig:
    """The sweep config of the start record (to resume with the run's own plan, not today's file).

    Raises:
        FormatError: the start record has no such section, it is invalid, or the points it gives
            differ from the stored plan (plan generation changed between versions).
    """
    path = str(record.run_dir / RUN_LOG)
    config = record.start.get("config", {})
    if not isinstance(config, dict) or section not in config:
        raise FormatError(f"the start record has no '{section}' config to resume from", path=path, offset=0)
    try:
        sweep = from_mapping(SweepConfig, config[section], path=path, key=f"config.{section}")
    except ConfigError as exc:
        raise FormatError(f"stored sweep config is invalid: {exc}", path=path, offset=0) from exc
    if [p.point_id for p in plan_points(sweep)] != record.planned_ids:
        raise FormatError("the stored plan differs from the one its config gives now", path=path, offset=0)
    return sweep


def completed_points(run_dir: str | Path) -> set[str]:
    """Ids of the points whose latest record has status ``done`` (skip these on resume)."""
    return {pid for pid, p in read_run(run_dir).latest_points().items() if p.status == "done"}


class RunLog:
    """Appends records to a run's log; create with :meth:`create` or :meth:`resume`."""

    def __init__(self, run_dir: Path, handle: Any) -> None:
        self.run_dir = run_dir
        self.path = run_dir / RUN_LOG
        self._handle = handle
        _make_reserve(run_dir / RESERVE)

    @classmethod
    def create(
        cls, run_dir: str | Path, *, run_id: str, config: Mapping[str, Any], plan: Sequence[Point],
        t_unix: float | None = None, command: str | None = None,
    ) -> RunLog:  # fmt: skip
        """Make the run folder (and ``points/``) and write the start record (``command``: the command
        line that made the run, stored when given).

        Raises:
            FormatError: the folder already holds a run log (resume it instead).
        """
        run_dir = Path(run_dir)
        (run_dir / POINTS_DIR).mkdir(parents=True, exist_ok=True)
        try:
            handle = open(run_dir / RUN_LOG, "xb", buffering=0)  # noqa: SIM115 - closed by close()
        except FileExistsError as exc:
            raise FormatError("a run log exists already; resume the run instead", path=str(run_dir / RUN_LOG)) from exc
        _fsync_dir(run_dir)
        runlog = cls(run_dir, handle)
        plan_json = [
            {"point_id": p.point_id, "index": p.index, "branch": p.branch.value, "speed_mps": p.speed_mps} for p in plan
        ]
        runlog._append({"type": "start", "run_id": run_id, "t_unix": _now(t_unix), "flagtrack_version": __version__,
                        "config": to_mapping(dict(config)), "plan": plan_json,
                        **({} if command is None else {"command": command})})  # fmt: skip
        return runlog

    @classmethod
    def resume(
        cls, run_dir: str | Path, *, t_unix: float | None = None, command: str | None = None
    ) -> tuple[RunLog, RunRecord]:
        """Reopen a run for appending: cut a torn last line, write a ``resume`` record (with
        ``command``, the command line resuming it, when given).

        Returns:
            The writer and what the log held before resuming.
        """
        record = read_run(run_dir)
        run_dir = Path(run_dir)
        handle = open(run_dir / RUN_LOG, "r+b", buffering=0)  # noqa: SIM115 - closed by close()
        if record.torn_tail:
            handle.truncate(record.valid_bytes)
            os.fsync(handle.fileno())
        handle.seek(record.valid_bytes)
        runlog = cls(run_dir, handle)
        done = sorted(pid for pid, p in record.latest_points().items() if p.status == "done")
        resume = {"type": "resume", "t_unix": _now(t_unix), "done": done, "cut_torn_tail": record.torn_tail}
        runlog._append({**resume, **({} if command is None else {"command": command})})
        return runlog, record

    def point(self, result: PointResult) -> None:
        """Append one point record (with the old keys of :data:`~.quantities.POINT_ALIASES` too)."""
        record = point_record(result)
        self._append({"type": "point", **record})

    def stop(self, reason: str, *, error: str | None = None, t_unix: float | None = None) -> None:
        """Append the stop record (``finished``, ``SIGTERM``, ``error``, ...); the reserve is given back
        (a resume makes a new one)."""
        self._append({"type": "stop", "t_unix": _now(t_unix), "reason": reason, "error": error})
        try:
            (self.run_dir / RESERVE).unlink(missing_ok=True)
        except OSError as exc:  # the record is written; only the reserve stays (a resume reuses it)
            log.warning("%s: could not give back the run's reserve: %s", self.run_dir / RESERVE, exc.strerror or exc)

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._handle.closed:
            self._handle.close()

    def __enter__(self) -> RunLog:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _append(self, record: dict[str, Any]) -> None:
        line = json.dumps({"type": record["type"], "v": LOG_VERSION, **record}, allow_nan=False)
        data = (line + "\n").encode()
        start = self._handle.tell()
        try:
            _write_all(self._handle, data)
        except OSError as exc:  # a full disk: give up the reserve, write the record there
            reserve = self.run_dir / RESERVE
            if exc.errno not in (errno.ENOSPC, errno.EDQUOT) or not reserve.exists():
                self._handle.truncate(start)
                raise
            log.warning("%s: the disk is full; using the run's reserve for the log", self.path)
            reserve.unlink()
            self._handle.truncate(start)
            self._handle.seek(start)
            _write_all(self._handle, data)
        os.fsync(self._handle.fileno())


def _write_all(handle: Any, data: bytes) -> None:
    """Write all of ``data`` to an unbuffered binary file (raw writes may be short)."""
    view = memoryview(data)
    while view:
        view = view[handle.write(view) :]


def _make_reserve(path: Path) -> None:
    """Hold :data:`RUN_LOG_RESERVE_BYTES` of disk for the run's last records (given up when the disk is full)."""
    if path.exists():
        return
    try:
        reserve = DiskReserve(path, RUN_LOG_RESERVE_BYTES)
        reserve.take()
        reserve.leave()  # (kept across resumes; removed by the stop record or spent on a full disk)
    except OSError as exc:
        log.warning("%s: no reserve for the run log's last records: %s", path, exc.strerror or exc)


def _now(t_unix: float | None) -> float:
    return time.time() if t_unix is None else t_unix


def _fsync_dir(path: Path) -> None:
    """Make a new file's directory entry durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
