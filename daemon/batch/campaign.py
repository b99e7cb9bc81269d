"""A batch from start to end: plan the work, hand the tasks to the executor, collect the rows, write
``batch.csv`` / ``batch.json`` (and the campaign figure of sweep runs)."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.batch.executor import Executor
from flagtrack.daemon.batch.figures import CAMPAIGN_FIGURE, plot_campaign, read_points
from flagtrack.daemon.batch.folders import FolderLock, remove_partial_outputs
from flagtrack.daemon.batch.inputs import OUTPUT_SUFFIX
from flagtrack.daemon.batch.progress import Progress
from flagtrack.daemon.batch.rows import CSV_NAME, JSON_NAME, Row, count, failed_row, write_csv, write_json
from flagtrack.daemon.batch.stamp import InputStat, params_digest
from flagtrack.daemon.batch.tasks import TaskResult, read_run_stamp, reconstruct_task, validate_task

if TYPE_CHECKING:
    from flagtrack.daemon.sweep.runlog import RunRecord
    from flagtrack.daemon.tracking.setup import TrackingSetup
    from flagtrack.drivers.sensor.setup import SensorConfig

log = logging.getLogger(__name__)

VALIDATION_WINDOW_S = 0.3  # flagtrack validate's default --window


@dataclass(frozen=True)
class Job:
    """One reconstruction: the recording, its centreline file, the recording's size (bytes)."""

    input: Path
    output: Path
    nbytes: int


def jobs_for(inputs: Sequence[Path], outputs: Sequence[Path]) -> list[Job]:
    """The jobs of resolved ``inputs`` and their ``outputs`` (sizes from the file system)."""
    return [Job(i, o, InputStat.of(i).size) for i, o in zip(inputs, outputs, strict=True)]


@dataclass
class BatchResult:
    """What a batch did: its rows (input order), the files it wrote, its wall time and counts."""

    rows: list[Row]
    csv: Path
    json: Path
    seconds: float
    figure: Path | None = None
    counts: dict[str, int] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The ``--json`` object: files written, counts, seconds and rows."""
        return {
            "csv": str(self.csv),
            "json": str(self.json),
            "figure": str(self.figure) if self.figure else None,
            "seconds": self.seconds,
            "counts": self.counts,
            "rows": [r.as_dict() for r in self.rows],
        }


class _Loop:
    """Tasks in flight, each with what it is for; :meth:`results` yields them as they finish (tasks may be
    submitted while it runs)."""

    def __init__(self, executor: Executor) -> None:
        self.executor = executor
        self.running: dict[Any, tuple[Any, str]] = {}

    def submit(self, key: Any, name: str, fn: Callable[..., TaskResult], *args: Any) -> None:
        self.running[self.executor.submit(fn, *args)] = (key, name)

    def results(self) -> Iterator[tuple[Any, TaskResult]]:
        while self.running:
            done, _ = self.executor.wait(self.running)
            for future in done:
                key, name = self.running.pop(future)
                try:
                    result = future.result()
                except Exception as exc:  # noqa: BLE001 - the task never returned: its row says why
                    reason = (
                        f"{name}: no result from its worker, which died or cannot run it ({type(exc).__name__}: {exc})"
                    )
                    result = TaskResult(failed_row(name, reason))
                yield key, result


def _detail(row: Row) -> str:
    if row.status == "failed":
        return row.error or ""
    if row.status == "skipped":
        return ""
    events = f"{row.events / 1e6:.2f} M events, " if row.events is not None else ""
    return f"({events}{row.updates} updates, {row.seconds:.2f} s on {row.worker})"


def _report(progress: Progress, name: str, nbytes: int, result: TaskResult) -> None:
    for warning in result.warnings:
        progress.line(f"warning: {warning}")
    progress.advance(name, nbytes, result.row.status, result.row.events, _detail(result.row))


def reconstruct_campaign(
    jobs: Sequence[Job],
    out_dir: Path,
    setup: TrackingSetup,
    executor_factory: Callable[[int], Executor],
    *,
    force: bool = False,
    checksum: bool = False,
    bar: bool = False,
    prefix: str = "flagtrack batch",
    strict: bool = False,
) -> BatchResult:
    """Reconstruct every job's recording into its centreline file, as ``flagtrack reconstruct`` does
    (``strict``: a damaged recording fails instead of losing its corrupt stretches).

    With ``out_dir`` locked (one batch at a time), the temporary files a killed batch left are removed,
    the tasks run on the executor ``executor_factory(len(jobs))`` gives, and ``batch.csv`` /
    ``batch.json`` are written in ``out_dir``. Outputs up to date are skipped unless ``force``.

    Raises:
        ConfigError: another batch writes into ``out_dir``; the executor cannot start.
    """
    started = time.monotonic()
    params = params_digest(setup.attrs)
    with FolderLock(out_dir):
        removed = remove_partial_outputs(job.output for job in jobs)
        with ExitStack() as stack:
            progress = stack.enter_context(Progress(prefix, len(jobs), sum(j.nbytes for j in jobs), bar=bar))
            if removed:
                progress.line(f"removed {len(removed)} unfinished output(s) of an interrupted batch")
            executor = stack.enter_context(executor_factory(len(jobs)))
            loop = _Loop(executor)
            for job in jobs:
                loop.submit(
                    job,
                    str(job.input),
                    reconstruct_task,
                    str(job.input),
                    str(job.output),
                    setup,
                    params,
                    force,
                    checksum,
                    strict,
                )
            rows: dict[Path, Row] = {}
            for job, result in loop.results():
                rows[job.input] = result.row
                _report(progress, job.input.name, job.nbytes, result)
        ordered = [rows[job.input] for job in jobs]
        seconds = time.monotonic() - started
        document = {
            "command": "batch reconstruct",
            "executor": executor.description,
            "workers": executor.workers,
            "out_dir": str(out_dir),
            "parameters": setup.attrs,
            "params_blake2b": params,
            "seconds": seconds,
            "counts": count(ordered),
            "rows": [r.as_dict() for r in ordered],
        }
        csv_path = write_csv(ordered, out_dir / CSV_NAME)
        json_path = write_json(document, out_dir / JSON_NAME)
    return BatchResult(ordered, csv_path, json_path, seconds, counts=count(ordered))


@dataclass(frozen=True)
class RunPlan:
    """One sweep run of ``batch validate``: its points' reconstructions and its validation.

    Attributes:
        run_dir: the run folder, resolved.
        setup: the tracking set-up its points are reconstructed with (None if ``error``).
        sensor: the run's ``sensor:`` section (None if ``error``).
        points: (point id, reconstruction) of each point ``flagtrack validate --reconstruct`` reconstructs
            (a sensor record and a raw file).
        stamp: what its validation is made from (parameters, points, run log): equal to the stamp of the
            last validation, with every point up to date, the run is skipped.
        error: why the run cannot be validated (its log unreadable, no sensor section), else None.
    """

    run_dir: Path
    setup: TrackingSetup | None
    sensor: SensorConfig | None
    points: tuple[tuple[str, Job], ...] = ()
    stamp: dict[str, Any] = field(default_factory=dict)
    error: str | None = None

    @property
    def validation_dir(self) -> Path:
        """``RUN_DIR/validation``, where ``flagtrack validate`` writes."""
        return self.run_dir / "validation"

    @property
    def centrelines_dir(self) -> Path:
        """``RUN_DIR/validation/centrelines``, where ``flagtrack validate --reconstruct`` writes them."""
        return self.validation_dir / "centrelines"


def plan_run(run_dir: Path, setup_for: Callable[[RunRecord], TrackingSetup]) -> RunPlan:
    """Plan the validation of the run in ``run_dir`` (resolved) with the set-up ``setup_for(record)`` gives.

    A run whose log cannot be read or that has no sensor section gets a plan with its ``error``.

    Raises:
        ConfigError: the tracking parameters for this run are invalid.
    """
    from flagtrack.daemon.errors import FormatError
    from flagtrack.daemon.sweep.runlog import RUN_LOG, read_run
    from flagtrack.daemon.validation.run import run_sensor_config

    try:
        record = read_run(run_dir)
        sensor = run_sensor_config(record, str(run_dir / RUN_LOG))
    except FormatError as exc:
        return RunPlan(run_dir, None, None, error=str(exc))
    setup = setup_for(record)
    plan = RunPlan(run_dir, setup, sensor)
    points = []
    for point in record.latest_points().values():
        if point.sensor_file is None or not point.raw_file:
            continue  # validate_run passes it through, or reports "no centrelines file"
        raw = run_dir / point.raw_file
        if raw.is_file():
            output = plan.centrelines_dir / f"{point.point_id}{OUTPUT_SUFFIX}"
            points.append((point.point_id, Job(raw.resolve(), output, InputStat.of(raw).size)))
    log_stat = InputStat.of(run_dir / RUN_LOG)
    stamp = {
        "params_blake2b": params_digest(setup.attrs),
        "points": [pid for pid, _ in points],
        "run_log": [log_stat.size, log_stat.mtime_ns],
        "window_s": VALIDATION_WINDOW_S,
    }
    return RunPlan(run_dir, setup, sensor, tuple(points), stamp)


@dataclass
class _RunState:
    plan: RunPlan
    waiting: set[str]
    rows: dict[str, Row] = field(default_factory=dict)


def validate_campaign(
    plans: Sequence[RunPlan],
    out_dir: Path,
    executor_factory: Callable[[int], Executor],
    *,
    force: bool = False,
    checksum: bool = False,
    bar: bool = False,
    prefix: str = "flagtrack batch",
) -> BatchResult:
    """Validate every planned run as ``flagtrack validate --reconstruct`` does, with its points'
    reconstructions spread over the executor's workers; then one row per run in ``OUT_DIR/batch.csv``,
    ``batch.json`` (with each point's row) and the campaign figure ``OUT_DIR/campaign.png``.

    A run is validated once all its points are reconstructed (or up to date); a run whose points are all up
    to date and whose last validation was made from the same stamp is skipped; a point that fails fails
    its run (the run's validation is then not rewritten).

    Raises:
        ConfigError: another batch writes into ``out_dir`` or a run's validation folder; the executor
            cannot start.
    """
    started = time.monotonic()
    jobs = [job for plan in plans for _, job in plan.points]
    with ExitStack() as locks:
        locks.enter_context(FolderLock(out_dir))
        for plan in plans:
            if plan.error is None:
                locks.enter_context(FolderLock(plan.validation_dir))
        removed = remove_partial_outputs(job.output for job in jobs)
        run_rows: dict[Path, Row] = {}
        states: dict[Path, _RunState] = {}
        with ExitStack() as stack:
            progress = stack.enter_context(Progress(prefix, len(jobs), sum(j.nbytes for j in jobs), bar=bar))
            if removed:
                progress.line(f"removed {len(removed)} unfinished output(s) of an interrupted batch")
            executor = stack.enter_context(executor_factory(max(len(jobs), len(plans), 1)))
            loop = _Loop(executor)
            for plan in plans:
                if plan.error is not None:
                    run_rows[plan.run_dir] = failed_row(plan.run_dir, plan.error)
                    progress.line(f"{plan.run_dir.name}: failed: {plan.error}")
                    continue
                state = states[plan.run_dir] = _RunState(plan, {pid for pid, _ in plan.points})
                params = plan.stamp["params_blake2b"]
                for pid, job in plan.points:
                    loop.submit(
                        (plan.run_dir, pid, job),
                        str(job.input),
                        reconstruct_task,
                        str(job.input),
                        str(job.output),
                        plan.setup,
                        params,
                        force,
                        checksum,
                    )
                if not plan.points:
                    _finish_points(state, loop, force, run_rows, progress)
            for key, result in loop.results():
                if isinstance(key, Path):  # a run's validation
                    state = states[key]
                    run_rows[key] = _run_row(state, result.row)
                    for warning in result.warnings:
                        progress.line(f"warning: {warning}")
                    _say_run(progress, run_rows[key])
                    continue
                run_dir, pid, job = key
                state = states[run_dir]
                state.rows[pid] = result.row
                state.waiting.discard(pid)
                _report(progress, f"{run_dir.name}/{pid}", job.nbytes, result)
                if not state.waiting:
                    _finish_points(state, loop, force, run_rows, progress)
        ordered = [run_rows[plan.run_dir] for plan in plans]
        figure = _campaign_figure(ordered, out_dir)
        seconds = time.monotonic() - started
        document = {
            "command": "batch validate",
            "executor": executor.description,
            "workers": executor.workers,
            "out_dir": str(out_dir),
            "seconds": seconds,
            "counts": count(ordered),
            "rows": [r.as_dict() for r in ordered],
            "figure": str(figure) if figure else None,
            "runs": [_run_document(plan, states.get(plan.run_dir)) for plan in plans],
        }
        csv_path = write_csv(ordered, out_dir / CSV_NAME)
        json_path = write_json(document, out_dir / JSON_NAME)
    return BatchResult(ordered, csv_path, json_path, seconds, figure, count(ordered))


def _finish_points(state: _RunState, loop: _Loop, force: bool, run_rows: dict[Path, Row], progress: Progress) -> None:
    """Every point of a run is reconstructed: validate the run, skip it (up to date), or fail it."""
    plan = state.plan
    failed = [r for r in state.rows.values() if r.status == "failed"]
    if failed:
        error = "; ".join(r.error or r.input for r in failed)
        run_rows[plan.run_dir] = _run_row(state, failed_row(plan.run_dir, f"{len(failed)} point(s) failed: {error}"))
        _say_run(progress, run_rows[plan.run_dir])
        return
    fresh = all(r.status == "skipped" for r in state.rows.values())
    csv_path = plan.validation_dir / "validation.csv"
    if not force and fresh and csv_path.is_file() and read_run_stamp(plan.validation_dir) == plan.stamp:
        row = Row(str(plan.run_dir), None, None, None, 0.0, "", "skipped", None, str(csv_path))
        run_rows[plan.run_dir] = _run_row(state, row)
        _say_run(progress, run_rows[plan.run_dir])
        return
    loop.submit(
        plan.run_dir,
        str(plan.run_dir),
        validate_task,
        str(plan.run_dir),
        plan.sensor,
        str(plan.centrelines_dir),
        plan.stamp,
        VALIDATION_WINDOW_S,
    )


def _run_row(state: _RunState, validation: Row) -> Row:
    """A run's row: its points' events, span, updates and seconds summed, the validation's status."""
    points = [r for r in state.rows.values() if r.status != "failed"]
    return Row(
        str(state.plan.run_dir),
        sum(r.events or 0 for r in points),
        sum(r.duration or 0.0 for r in points),
        sum(r.updates or 0 for r in points),
        sum(r.seconds for r in state.rows.values()) + validation.seconds,
        validation.worker,
        validation.status,
        validation.error,
        validation.output,
    )


def _say_run(progress: Progress, row: Row) -> None:
    name = Path(row.input).name
    if row.status == "failed":
        progress.line(f"run {name}: failed: {row.error}")
    elif row.status == "skipped":
        progress.line(f"run {name}: skipped (up to date)")
    else:
        progress.line(f"run {name}: validated in {row.seconds:.2f} s -> {row.output}")


def _campaign_figure(rows: Sequence[Row], out_dir: Path) -> Path | None:
    runs = [(Path(r.input).name, read_points(r.output)) for r in rows if r.status != "failed" and r.output]
    if not runs:
        return None
    n_points = sum(len(points) for _, points in runs)
    return plot_campaign(runs, out_dir / CAMPAIGN_FIGURE, f"campaign: {len(runs)} runs, {n_points} points")


def _run_document(plan: RunPlan, state: _RunState | None) -> dict[str, Any]:
    points = state.rows if state is not None else {}
    return {
        "run_dir": str(plan.run_dir),
        "parameters": plan.setup.attrs if plan.setup is not None else None,
        "params_blake2b": plan.stamp.get("params_blake2b"),
        "points": [{"point_id": pid, **points[pid].as_dict()} for pid, _ in plan.points if pid in points],
    }
