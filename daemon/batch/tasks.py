"""What a batch worker runs (in a local pool's process or a Dask worker): paths in, one row out.

A task gets the paths of its input and output (strings every worker resolves alike on the shared file
system) and the small tracking set-up; it reads the input and writes the output itself, and only its
:class:`~flagtrack.daemon.batch.rows.Row` (and the warnings the reading raised) goes back.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import socket
import sys
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.batch.rows import Row, Status, failed_row
from flagtrack.daemon.batch.stamp import DIGEST, InputStat, file_digest, read_stamp, stamp_attrs, up_to_date
from flagtrack.daemon.errors import FlagtrackError
from flagtrack.drivers.atomic import atomic_write

if TYPE_CHECKING:
    from flagtrack.daemon.tracking.setup import TrackingSetup
    from flagtrack.drivers.sensor.setup import SensorConfig

RUN_STAMP = "batch_stamp.json"
_DASK_TRIM_THRESHOLD = "65536"
_tuned = False


@dataclass(frozen=True)
class TaskResult:
    """A task's row and the warnings reading its input raised (damaged words skipped, a truncated end)."""

    row: Row
    warnings: tuple[str, ...] = ()


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def init_pool_worker() -> None:
    """Start of a local pool's worker: Ctrl-C is the parent's to handle; SIGTERM (the parent stopping it)
    unwinds, so the file being written is removed rather than left half-written."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    _tune()


def _exit_on_sigterm(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001 - a signal handler's signature
    raise SystemExit(128 + signum)


def _tune() -> None:
    """The process settings ``flagtrack`` applies before a command (once per worker process).

    A Dask nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (its default
    ``distributed.nanny.pre-spawn-environ``), which makes ``tune_process`` leave glibc's allocator alone:
    the tracker then page-faults on every chunk (1.2x the CPU, up to 1.5x the wall time, docs/batch.md).
    In a Dask worker that value is taken for Dask's, not the user's, and flagtrack's settings apply.
    """
    global _tuned
    if _tuned:
        return
    from flagtrack.daemon.process import tune_process

    if os.environ.get("MALLOC_TRIM_THRESHOLD_") == _DASK_TRIM_THRESHOLD and _in_dask_worker():
        del os.environ["MALLOC_TRIM_THRESHOLD_"]  # mallopt() now overrides what glibc read at start
    tune_process()
    _tuned = True


def _in_dask_worker() -> bool:
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return False
    try:
        distributed.get_worker()
    except ValueError:  # not in a worker's task
        return False
    return True


def reconstruct_task(
    input_file: str,
    output: str,
    setup: TrackingSetup,
    params: str,
    force: bool = False,
    checksum: bool = False,
    strict: bool = False,
) -> TaskResult:
    """Reconstruct ``input_file`` into ``output`` as ``flagtrack reconstruct`` does (written atomically,
    stamped), unless ``output`` is up to date (see :mod:`~flagtrack.daemon.batch.stamp`).

    Args:
        input_file: the recording, resolved.
        output: the centreline file.
        setup: the tracking set-up.
        params: :func:`~flagtrack.daemon.batch.stamp.params_digest` of ``setup.attrs``.
        force: redo it even if up to date.
        checksum: compare the input's content digest even when its size and time match.
        strict: a damaged recording fails (by default its corrupt stretches are skipped, with a warning).

    Returns:
        The row (``done``, ``skipped`` or ``failed`` with the reason naming the file); a failure is never
        raised, so one bad input stops nothing else.
    """
    from flagtrack.daemon.tracking.offline import reconstruct_file

    _tune()
    started, worker = time.perf_counter(), worker_name()
    caught: list[warnings.WarningMessage] = []
    try:
        resolved = str(Path(input_file).resolve())
        stat = InputStat.of(input_file)
        digest = None
        if not force:
            recorded = read_stamp(output)
            fresh = up_to_date(recorded, resolved, stat, params, checksum=checksum)
            if fresh is None and recorded is not None:
                digest = file_digest(input_file)
                fresh = digest == recorded[DIGEST]
            if fresh:
                return TaskResult(_row(input_file, output, "skipped", started, worker))
        digest = digest or file_digest(input_file)
        stamped = dataclasses.replace(setup, attrs={**setup.attrs, **stamp_attrs(stat, digest, params)})
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            check = _sensor_check(setup, input_file)
            reconstruct_file(Path(input_file), Path(output), stamped, atomic=True, strict=strict, check_sensor=check)
        if InputStat.of(input_file) != stat:
            Path(output).unlink(missing_ok=True)
            raise FlagtrackError(f"{resolved}: changed while it was being read (nothing written): run the batch again")
        row = _row(input_file, output, "done", started, worker)
    except FlagtrackError as exc:
        row = failed_row(input_file, str(exc), seconds=time.perf_counter() - started, worker=worker)
    except OSError as exc:
        reason = f"{exc.filename or input_file}: {exc.strerror or exc}"
        row = failed_row(input_file, reason, seconds=time.perf_counter() - started, worker=worker)
    except Exception as exc:  # noqa: BLE001 - whatever one input raises becomes its row; the others go on
        reason = f"{input_file}: {type(exc).__name__}: {exc}"
        row = failed_row(input_file, reason, seconds=time.perf_counter() - started, worker=worker)
    return TaskResult(row, tuple(f"{input_file}: {w.message}" for w in caught))


def _sensor_check(setup: TrackingSetup, input_file: str) -> Callable[[int, int], None]:
    """Refuse a calibration made on another sensor than the recording's and a root off it, as
    ``flagtrack reconstruct`` does (a root off the sensor gave nonsense centrelines, ``done``)."""
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.tracking.setup import calibration_misfit, root_on_sensor

    def check(width: int, height: int) -> None:
        misfit = calibration_misfit(setup.mapping, width, height, input_file)
        if misfit is not None:
            raise ConfigError(f"the calibration {setup.config.calibration}: {misfit}")
        if not root_on_sensor(setup, width, height):
            x, y = setup.params.chain.root
            raise ConfigError(f"{input_file}: the root ({x:g}, {y:g}) is off its {width} x {height} sensor")

    return check


def _row(input_file: str, output: str, status: Status, started: float, worker: str) -> Row:
    """A done or skipped row: events, updates and time span read back from the output."""
    import h5py

    with h5py.File(output, "r") as f:
        events = int(f.attrs["events_in"])
        t = f["t"]
        updates = int(t.shape[0])
        duration = float(t[-1] - t[0]) if updates >= 2 else 0.0
    seconds = time.perf_counter() - started
    return Row(input_file, events, duration, updates, seconds, worker, status, None, output)


def validate_task(
    run_dir: str, sensor: SensorConfig, centrelines_dir: str, stamp: Mapping[str, Any], window_s: float = 0.3
) -> TaskResult:
    """Recompute a sweep run's point-sensor comparison from the centrelines in ``centrelines_dir``, as
    ``flagtrack validate --reconstruct`` does after reconstructing them (``RUN_DIR/validation/``: one
    figure per point, ``validation.csv``, ``validation.png``), then record ``stamp`` beside them.

    Returns:
        A row with the seconds, the worker and ``validation.csv`` (events and updates are the points'),
        or ``failed`` with the reason.
    """
    from flagtrack.daemon.validation.run import validate_run

    _tune()
    started, worker = time.perf_counter(), worker_name()
    stamp_path = Path(centrelines_dir).parent / RUN_STAMP
    try:
        stamp_path.unlink(missing_ok=True)  # a validation cut short leaves no stamp
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            result = validate_run(run_dir, sensor=sensor, centrelines_dir=centrelines_dir, window_s=window_s)
        damaged = [f"{run_dir}: point {p.point_id} {p.sensor_status}" for p in result.damaged]
        if not damaged:  # (a run with a damaged point is validated again next time)
            atomic_write(stamp_path, json.dumps(dict(stamp), sort_keys=True) + "\n")
        seconds = time.perf_counter() - started
        row = Row(run_dir, None, None, None, seconds, worker, "done", None, str(result.csv.resolve()))
        return TaskResult(row, (*damaged, *(f"{run_dir}: {w.message}" for w in caught)))
    except FlagtrackError as exc:
        return TaskResult(failed_row(run_dir, str(exc), seconds=time.perf_counter() - started, worker=worker))
    except Exception as exc:  # noqa: BLE001 - whatever one run raises becomes its row; the others go on
        reason = f"{run_dir}: {type(exc).__name__}: {exc}"
        return TaskResult(failed_row(run_dir, reason, seconds=time.perf_counter() - started, worker=worker))


def read_run_stamp(validation_dir: Path) -> dict[str, Any] | None:
    """The stamp :func:`validate_task` left in a run's validation folder, or None."""
    try:
        return dict(json.loads((validation_dir / RUN_STAMP).read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError):
        return None
