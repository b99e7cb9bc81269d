"""The files of a point's attempts: a bad attempt's files set aside (measuring the point again
loses nothing), and whether the disk holds one more attempt."""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from flagtrack.daemon.sweep.runlog import POINTS_DIR, PointResult
from flagtrack.daemon.sweep.validity import expected_point_bytes, free_space_problem

log = logging.getLogger(__name__)


def set_aside(run_dir: Path, result: PointResult) -> PointResult:
    """Rename a bad attempt's files (``<id>.bad<N>.raw`` ...); return its record pointing at them."""
    points = run_dir / POINTS_DIR
    point_id = result.point_id
    n = 1
    while any(points.glob(f"{point_id}.bad{n}.*")) or any(points.glob(f"{point_id}.bad{n}_*")):
        n += 1
    moved: dict[str, str | None] = {}
    for old in sorted(points.glob(f"{point_id}[._]*")):
        if ".bad" in old.name or ".action" in old.name:
            continue
        new = old.with_name(f"{point_id}.bad{n}{old.name[len(point_id) :]}")
        try:
            os.replace(old, new)
        except OSError as exc:
            log.error("supervisor: could not set %s aside: %s", old, exc)
            continue
        moved[str(old.relative_to(run_dir))] = str(new.relative_to(run_dir))
    return replace(
        result,
        raw_file=moved.get(result.raw_file or "", result.raw_file),
        centreline_file=moved.get(result.centreline_file or "", result.centreline_file),
    )


def bytes_per_s(run_dir: Path, result: PointResult) -> float:
    """Bytes per second a recorded point wrote (its .raw and centreline files), 0 when unknown."""
    duration_s = result.t_stop_unix - result.t_start_unix
    if not duration_s > 0:
        return 0.0
    files = [run_dir / f for f in (result.raw_file, result.centreline_file) if f]
    return sum(f.stat().st_size for f in files if f.exists()) / duration_s


def space_problem(
    run_dir: Path,
    record_s: float,
    recorded: Iterable[PointResult],
    rate_mev_s: float,
    bytes_per_event: float,
    margin_mb: float,
) -> str | None:
    """Why the disk of ``run_dir`` cannot hold one more point, or None: the expected size comes from
    the configured rate and from the fastest rate the run's ``recorded`` points filled it at."""
    measured = [bytes_per_s(run_dir, p) for p in recorded]
    need = expected_point_bytes(record_s, rate_mev_s, bytes_per_event, max(measured, default=0.0))
    free = shutil.disk_usage(run_dir).free
    return free_space_problem(free, need, margin_mb * 1e6, str(run_dir))
