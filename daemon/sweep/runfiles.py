"""What a sweep run folder says about itself: ``README.txt`` for a person, ``run.json`` for a program.

Both are made from the run log (``run.jsonl``, which stays the reference) each time the summary is
written: at the end of every session of a run, so a resumed run's are up to date. A run folder
copied to a colleague then explains itself: what each file holds, the command that made it, the
flagtrack version, the plan, the points with their figures, the onset and decay found.

``run.json`` (``format`` ``flagtrack-sweep-run``, ``format_version`` 1) holds: ``run_id``,
``flagtrack_version`` (that started the run) and ``written_by`` (that wrote this file),
``started_unix``, ``started`` (ISO 8601, local time), ``command``, ``resumes`` (``t_unix``,
``command``, ``done``), ``status`` and ``status_detail`` (:func:`run_status`), ``stop`` (the last
stop record), ``onset_mps`` and ``decay_mps`` (``null`` where not observed), ``counts`` (planned,
done, failed), ``plan`` (the sweep section and the planned points), ``rig`` (the rest of the
config the run was made with), ``points`` (the latest record of each point, in plan order, every
figure of the summary's columns, ``null`` for a missing number) and ``files`` (``path``, ``what``,
``bytes`` of every file of the folder that flagtrack wrote).
"""

from __future__ import annotations

import fnmatch
import json
import math
import shlex
import sys
import textwrap
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flagtrack.daemon import __file__ as _daemon_init
from flagtrack.daemon import __version__
from flagtrack.daemon.sweep.quantities import QUANTITIES
from flagtrack.daemon.sweep.runlog import RUN_LOG, PointResult, RunRecord, point_record
from flagtrack.drivers.atomic import atomic_write

RUN_JSON = "run.json"
README = "README.txt"
RUN_JSON_FORMAT = "flagtrack-sweep-run"
RUN_JSON_VERSION = 1
_MAIN = (Path(_daemon_init).parent / "__main__.py").resolve()  # what ``python -m flagtrack.daemon`` runs

# (pattern relative to the run folder, what the file is), in the order README.txt lists them
FILE_KINDS: tuple[tuple[str, str], ...] = (
    (README, "this file: what the run is and what each file holds"),
    (
        RUN_LOG,
        "the run log, the reference: a start record (command, flagtrack version, the whole rig config, the "
        "plan), one record per measured point, a record per resumed session, a stop record with the reason "
        "(JSON lines, append-only)",
    ),
    (RUN_JSON, "the run as one JSON object for programs: plan, points and their figures, onset and decay, files"),
    ("summary.csv", "one row per point (its latest record): speed, branch, flag state, A/L, f, ...; NaN: no number"),
    (
        "amplitude.png",
        "tip amplitude A/L (bars: its std cycle by cycle) and the event rate against the wind speed, "
        "onset and decay marked (paper 5h)",
    ),
    (
        "validation.png",
        "point-sensor error (|e|/L mean and std over time, e/L RMS) and event-cloud distance "
        "(Delta_RMS/L mean and std over time), in % of L, against the wind speed (paper 5g)",
    ),
    ("validation/*", "flagtrack validate's recomputed point-sensor comparison"),
    ("points/*.raw", "the point's events (EVT 3.0 .raw; flagtrack events info FILE)"),
    (
        "points/*_centrelines.h5",
        "the point's centrelines (HDF5: /t, /s, /x, /y, joints, the event-cloud distance "
        "/delta_rms, each with its units and description; parameters at the root; docs/formats.md)",
    ),
    ("points/*_sensor.h5", "the point sensor's samples and trigger pulses, on the sensor's clock (docs/sensor.md)"),
    (
        "points/*_sensor.png",
        "the point sensor against the reconstruction at the beam, e/L and Delta_RMS/L over an "
        "excerpt of the point (its statistics in the panels, the whole point's in the title) (paper 5c-e)",
    ),
    ("points/*.action*.log", "what the point's actions printed"),
    ("points/*.json", "the recording's sidecar: camera, counts, sequence gaps, the rig config"),
)


def command_line(argv: Sequence[str] | None = None) -> str:
    """The command line of this process as a user would type it (``flagtrack sweep -c rig.yaml``)."""
    argv = list(sys.argv if argv is None else argv)
    if not argv:
        return ""
    program = Path(argv[0])
    if program.name == "flagtrack" or program.resolve() == _MAIN:  # the script, or python -m flagtrack.daemon
        return shlex.join(["flagtrack", *argv[1:]])
    return shlex.join(argv)


def run_status(record: RunRecord) -> tuple[str, str]:
    """How the run ended: (``finished`` | ``stopped`` | ``error`` | ``incomplete``, detail).

    ``incomplete``: no stop record after the last start or resume (the run is going on, or was
    killed: resume it).
    """
    stop = record.stop
    last_begin = max([record.start.get("t_unix", 0.0), *(r.get("t_unix", 0.0) for r in record.resumes)])
    if stop is None or stop.get("t_unix", 0.0) < last_begin:
        return "incomplete", "no stop record: running, or killed (resume it)"
    reason = str(stop.get("reason", ""))
    if reason == "finished":
        return "finished", ""
    if reason == "error":
        return "error", str(stop.get("error") or "")
    return "stopped", reason


def describe_run(
    record: RunRecord, points: Sequence[PointResult], onset_mps: float | None, decay_mps: float | None
) -> dict[str, Any]:
    """The ``run.json`` object of a run (module docstring); ``points``: the latest record of each."""
    start = record.start
    config = dict(start.get("config") or {})
    status, detail = run_status(record)
    return {
        "format": RUN_JSON_FORMAT,
        "format_version": RUN_JSON_VERSION,
        "run_id": start.get("run_id"),
        "flagtrack_version": start.get("flagtrack_version"),
        "written_by": __version__,
        "started_unix": start.get("t_unix"),
        "started": _iso(start.get("t_unix")),
        "command": start.get("command"),
        "resumes": [
            {"t_unix": r.get("t_unix"), "command": r.get("command"), "done": r.get("done")} for r in record.resumes
        ],
        "status": status,
        "status_detail": detail,
        "stop": record.stop,
        "onset_mps": onset_mps,
        "decay_mps": decay_mps,
        "counts": {
            "planned": len(record.planned_ids),
            "done": sum(p.status == "done" for p in points),
            "failed": sum(p.status == "failed" for p in points),
            "lossy": sum(p.status == "lossy" for p in points),
        },
        "plan": {"sweep": config.pop("sweep", None), "points": start.get("plan", [])},
        "rig": config,
        "points": [point_record(p) for p in points],
        "files": [{"path": path, "what": what, "bytes": size} for path, what, size in _files(record.run_dir)],
    }


def write_run_files(
    record: RunRecord, points: Sequence[PointResult], onset_mps: float | None, decay_mps: float | None
) -> tuple[Path, Path]:
    """Write ``run.json`` and ``README.txt`` in the run's folder (each atomically); return their paths."""
    run_dir = record.run_dir
    description = describe_run(record, points, onset_mps, decay_mps)
    json_path = atomic_write(run_dir / RUN_JSON, json.dumps(description, indent=1, allow_nan=False) + "\n")
    readme_path = atomic_write(run_dir / README, readme_text(description))
    return json_path, readme_path


def readme_text(run: dict[str, Any]) -> str:
    """``README.txt`` of a run, from its ``run.json`` object."""
    counts = run["counts"]
    lines = [
        f"Sweep run {run['run_id']}: a wind-speed sweep recorded by flagtrack {run['flagtrack_version']}",
        "",
        f"Started    {run['started'] or '?'}",
        f"Command    {run['command'] or '(not recorded)'}",
    ]
    lines += [
        f"Resumed    {_iso(r['t_unix']) or '?'}  {r['command'] or '(command not recorded)'}" for r in run["resumes"]
    ]
    status = run["status"] + (f" ({run['status_detail']})" if run["status_detail"] else "")
    lines += [
        f"Status     {status}; {counts['done']} of {counts['planned']} points done"
        + (f", {counts['failed']} failed" if counts["failed"] else "")
        + (f", {counts['lossy']} lossy" if counts.get("lossy") else ""),
        f"Onset      {speed_text(run['onset_mps'])} going up (first flapping point after a still one)",
        f"Decay      {speed_text(run['decay_mps'])} coming down (first still point after a flapping one)",
        f"Plan       {_plan_text(run['plan']['sweep'])}",
        f"Written by flagtrack {run['written_by']} from run.jsonl (rewritten with the summary)",
        "",
        "Files",
    ]
    present = run["files"]
    for pattern, what in FILE_KINDS:
        matching = [f["path"] for f in present if _kind(f["path"]) == pattern]
        if not matching:
            continue
        shown = matching[0] if len(matching) == 1 else f"{pattern}  ({len(matching)} files)"
        lines.append(f"  {shown}")
        lines += textwrap.wrap(what, 100, initial_indent="      ", subsequent_indent="      ")
    lines += ["", "Points (the latest record of each; the numbers are below)", _point_header()]
    lines += [_point_row(p) for p in run["points"]]
    lines += ["", "Numbers: each column, its key in run.json and summary.csv (there a fraction where the column "
              "says %: 0.0036 for 0.36 %), what it is"]  # fmt: skip
    for key in README_COLUMNS:
        q = QUANTITIES[key]
        lines += textwrap.wrap(f"{q.heading:<21} {key}: {q.meaning}", 100, initial_indent="  ",
                               subsequent_indent=" " * 24)  # fmt: skip
    lines += [
        "",
        "Resume an interrupted run with: flagtrack sweep --resume RUN_DIR",
        "Recompute the point-sensor comparison with: flagtrack validate RUN_DIR",
        "",
    ]
    return "\n".join(lines)


def _plan_text(sweep: Any) -> str:
    if not isinstance(sweep, dict):
        return "?"
    if isinstance(sweep.get("range"), dict):
        r = sweep["range"]
        speeds = f"{r.get('start')} to {r.get('stop')} m/s in {r.get('step')} m/s steps"
    else:
        speeds = f"speeds {', '.join(str(v) for v in sweep.get('speeds') or [])} m/s"
    branches = ", ".join(str(b) for b in sweep.get("branches") or [])
    return (
        f"{speeds}, branches {branches}; settle {sweep.get('settle_s')} s, record {sweep.get('record_s')} s per point"
    )


#: The numbers of a point README.txt shows, in its columns' order (their labels and units: ``quantities``).
README_COLUMNS = (
    "speed_mps", "amplitude_over_l", "frequency_hz", "lost_fraction", "stale_fraction", "sensor_error_rms_over_l",
    "cloud_distance_mean_over_l",
)  # fmt: skip
_WIDTHS = {"speed_mps": 8, "amplitude_over_l": 6, "frequency_hz": 6, "lost_fraction": 8, "stale_fraction": 9}


def _point_header() -> str:
    numbers = [QUANTITIES[key].heading.rjust(_WIDTHS.get(key, len(QUANTITIES[key].heading))) for key in README_COLUMNS]
    return f"  {'point':<16} {'branch':<6} {'state':<9} {'status':<7} " + " ".join(numbers)


def _point_row(point: dict[str, Any]) -> str:
    numbers = [
        QUANTITIES[key].number(point.get(key)).rjust(_WIDTHS.get(key, len(QUANTITIES[key].heading)))
        for key in README_COLUMNS
    ]
    head = f"  {point['point_id']:<16} {point['branch']:<6} {point['state']:<9} {point['status']:<7} "
    return head + " ".join(numbers)


def speed_text(value: float | None) -> str:
    """An onset or decay speed as README.txt and ``flagtrack sweep`` say it (``not observed``: None)."""
    return "not observed" if value is None else f"{value:g} m/s"


def _kind(path: str) -> str | None:
    """The pattern of :data:`FILE_KINDS` a file of the run folder matches first, or None."""
    return next((pattern for pattern, _ in FILE_KINDS if fnmatch.fnmatchcase(path, pattern)), None)


def _files(run_dir: Path) -> list[tuple[str, str, int | None]]:
    """(path relative to the run folder, what it is, bytes) of every file flagtrack wrote there;
    ``run.json`` and ``README.txt`` are listed without a size (they are being written)."""
    described = dict(FILE_KINDS)
    found: list[tuple[str, str, int | None]] = [
        (README, described[README], None),
        (RUN_JSON, described[RUN_JSON], None),
    ]
    for path in sorted(p for p in run_dir.rglob("*") if p.is_file()):
        relative = path.relative_to(run_dir).as_posix()
        kind = _kind(relative)
        if kind is not None and relative not in (README, RUN_JSON):
            found.append((relative, described[kind], path.stat().st_size))
    return found


def _iso(t_unix: Any) -> str | None:
    if not isinstance(t_unix, int | float) or not math.isfinite(t_unix):
        return None
    return time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(t_unix))
