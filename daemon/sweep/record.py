"""A point's ``Record`` and ``Action`` steps, carried out in a :class:`~.session.Session`.

Recording: the recorder is started, the point's measure gathers while the session waits (the
point's tunnel watch and the recorder's errors can spoil it: BadPoint, its files named in its
record), then the recorder is stopped and the record is made of what the measure found, the
tunnel's readbacks and the recorder's replies.
"""

from __future__ import annotations

import logging
import math
import uuid
from dataclasses import replace
from pathlib import Path

import numpy as np

from flagtrack.daemon.schema import RecorderCommand
from flagtrack.daemon.sweep.actions import ActionOutcome, PauseAction, parse_action, run_command
from flagtrack.daemon.sweep.plan import Action, Point, Record
from flagtrack.daemon.sweep.ports import PointMeasure
from flagtrack.daemon.sweep.progress import is_suspect
from flagtrack.daemon.sweep.runlog import POINTS_DIR, PointResult, point_paths
from flagtrack.daemon.sweep.session import Session
from flagtrack.daemon.sweep.validity import BadPoint, PointWatch, recording_problem

log = logging.getLogger(__name__)


def record_point(
    session: Session, measure: PointMeasure, step: Record, run_dir: Path, previous_state: str, suspect_bound: float
) -> PointResult:
    """Record the point under way (``session.point``) for ``step.duration_s``; return its record.

    Raises:
        BadPoint: the point was spoilt while it recorded (its record names the files so far).
    """
    watch = session.point
    assert watch is not None
    point = watch.point
    t_start_unix = session.clock.time()
    base = run_dir / POINTS_DIR / point.point_id
    started, refused = session.start_recording(str(base.resolve()))
    if refused:  # nothing is recorded (a read-only folder, a full disk): the sweep stops safe
        raise BadPoint(PointResult.planned(point, status="failed", reason=refused), stop=True)
    try:
        readbacks = _gather(session, measure, watch, step.duration_s)
        stopped = session.ask_recorder(RecorderCommand("stop", request_id=uuid.uuid4().hex))
    except BadPoint as bad:  # the recording so far is kept (and named in the point's record)
        raise BadPoint(_with_files(bad.result, run_dir, t_start_unix, session.clock.time()), bad.stop) from None
    found = measure.result(point, run_dir, previous_state)
    readback = [v for v in readbacks if math.isfinite(v)]
    lost = recording_problem(started, stopped)
    raw, lines = (run_dir / path for path in point_paths(point.point_id))
    return replace(
        found,
        status="lossy" if lost else "done",
        reason=lost,
        speed_readback_mps=float(np.mean(readback)) if readback else math.nan,
        raw_bytes=raw.stat().st_size if raw.exists() else int(stopped.bytes),
        raw_file=str(raw.relative_to(run_dir)),
        centreline_file=_relative(lines, run_dir),
        t_start_unix=t_start_unix,
        t_stop_unix=session.clock.time(),
        suspect=is_suspect(found.lost_fraction, suspect_bound, found.stale_fraction, found.state, found.chain_reach),
    )


def _gather(session: Session, measure: PointMeasure, watch: PointWatch, duration_s: float) -> list[float]:
    """Let ``measure`` gather while the session waits ``duration_s``; return the tunnel's readbacks
    meanwhile. A point spoilt meanwhile (BadPoint) has its recording stopped (unless the recorder
    failed), with nothing more judged while the recorder stops."""
    measure.begin()
    watch.readbacks = []
    try:
        session.idle(duration_s)
    except BadPoint as bad:
        measure.end()
        watch.readbacks, watch.tunnel = None, None
        if not bad.stop:
            session.ask_recorder(RecorderCommand("stop", request_id=uuid.uuid4().hex))
        raise
    finally:
        readbacks, watch.readbacks = watch.readbacks, None
    measure.end()
    return readbacks or []


def _with_files(result: PointResult, run_dir: Path, t_start_unix: float, t_stop_unix: float) -> PointResult:
    """A spoilt attempt's record naming what its recording left (the raw and centreline files)."""
    raw, lines = (run_dir / path for path in point_paths(result.point_id))
    return replace(
        result,
        raw_file=_relative(raw, run_dir),
        raw_bytes=raw.stat().st_size if raw.exists() else 0,
        centreline_file=_relative(lines, run_dir),
        t_start_unix=t_start_unix,
        t_stop_unix=t_stop_unix,
    )


def _relative(path: Path, run_dir: Path) -> str | None:
    """``path`` relative to the run folder, None when it does not exist."""
    return str(path.relative_to(run_dir)) if path.exists() else None


def run_action(session: Session, step: Action, number: int, run_dir: Path) -> ActionOutcome:
    """Run one per-point action of the point under way (see :mod:`~flagtrack.daemon.sweep.actions`);
    the session keeps watching (stop requests still work)."""
    watch = session.point
    assert watch is not None
    point = watch.point
    action = parse_action(step.name, step.params)
    if isinstance(action, PauseAction):
        session.idle(action.seconds)
        return ActionOutcome(step.name, True, "", action.seconds)
    point_dir = run_dir / POINTS_DIR
    log_path = point_dir / f"{point.point_id}.action{number}.log"
    log.info("supervisor: action %s for %s", step.name, point.point_id)
    outcome = run_command(action, step.name, _context(point, run_dir), run_dir, log_path, idle=session.idle)
    if not outcome.ok:
        log.warning("supervisor: point %s: %s", point.point_id, outcome.summary())
    return outcome


def _context(point: Point, run_dir: Path) -> dict[str, object]:
    """The placeholders of a command action for ``point``."""
    raw, lines = point_paths(point.point_id)
    return {
        "point_id": point.point_id,
        "index": point.index,
        "branch": point.branch.value,
        "speed_mps": f"{point.speed_mps:g}",
        "run_dir": str(run_dir.resolve()),
        "point_dir": str((run_dir / POINTS_DIR).resolve()),
        "raw": str((run_dir / raw).resolve()),
        "centrelines": str((run_dir / lines).resolve()),
    }
