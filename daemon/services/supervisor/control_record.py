"""A control experiment's run folder: what the loop did, step by step, and what the folder holds.

- ``control.jsonl``: one JSON object per control step (``t_s`` seconds since the loop began,
  ``state`` the flag state the law saw, ``asked_mps``, ``applied_mps``, ``reason`` when they differ,
  ``setpoint_mps`` the set-point written, ``setpoint`` the law's own, ``latency_ms``, ``requester``
  ``law`` or the identity of a bus request), appended and flushed as the loop goes;
- ``recording.raw`` (+ ``recording.json``) and ``recording_centrelines.h5``: the camera and the
  centrelines of the whole run (the recorder's files);
- ``control.png``: A/L, f and the speed against time, with the set-point;
- ``run.json`` (``format`` ``flagtrack-control-run``) and ``README.txt``: the run for a program and
  for a person, written at the start and again at the end.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import IO, Any

import numpy as np

from flagtrack.daemon import __version__
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.runfiles import command_line
from flagtrack.daemon.sweep.runlock import RunLock
from flagtrack.drivers.atomic import atomic_write

CONTROL_LOG, RUN_JSON, README, FIGURE = "control.jsonl", "run.json", "README.txt", "control.png"
RECORDING = "recording"
"""The recorder's base name in the folder (``recording.raw``, ``recording_centrelines.h5``)."""
RUN_JSON_FORMAT, RUN_JSON_VERSION = "flagtrack-control-run", 1
FILES: tuple[tuple[str, str], ...] = (
    (README, "this file: what the run is and what each file holds"),
    (RUN_JSON, "the run as one JSON object for programs: the law, how it ended, counts, latency, files"),
    (CONTROL_LOG, "one record per control step: t_s, the state the law saw, asked_mps, applied_mps, reason"),
    (FIGURE, "A/L, f and the wind speed against time, with the set-point"),
    (f"{RECORDING}.raw", "the camera's events of the whole run (EVT 3.0 .raw; flagtrack events info FILE)"),
    (f"{RECORDING}.json", "the recording's sidecar: camera, counts, sequence gaps, the rig config"),
    (f"{RECORDING}_centrelines.h5", "the centrelines of the whole run (HDF5: /t, /s, /x, /y, joints, parameters)"),
)


class ControlRecord:
    """The run folder of one control run (see the module); :meth:`open` it, :meth:`write` each
    step, :meth:`close` it.

    Args:
        run_dir: the folder (made; refused if it holds a control log already).
        about: what ``run.json`` says of the run besides its records (the law, period, rig config).
    """

    def __init__(self, run_dir: Path, about: dict[str, Any]) -> None:
        self.run_dir, self.about = Path(run_dir).expanduser(), dict(about)
        self.steps, self.faults, self.requests = 0, 0, 0
        self.latencies_ms: list[float] = []
        self._log: IO[str] | None = None
        self._lock: RunLock | None = None
        self._started_unix = math.nan

    @property
    def recording_base(self) -> Path:
        """Where the recorder writes the run's recording (without extension)."""
        return self.run_dir / RECORDING

    def open(self, now_unix: float) -> None:
        """Make and lock the folder, start the control log and write ``run.json`` and ``README.txt``.

        Raises:
            ConfigError: the folder holds a control run already, or cannot be made (naming it).
        """
        if (self.run_dir / CONTROL_LOG).exists():
            raise ConfigError(f"{self.run_dir} holds a control run already; choose another folder", key="--out")
        self._lock = RunLock.acquire(self.run_dir, command_line())
        self._started_unix = now_unix
        self._log = open(self.run_dir / CONTROL_LOG, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self._write_description("running", "", None)

    def write(self, record: dict[str, Any]) -> None:
        """Append one step's record (numbers that are not finite are written as null)."""
        if self._log is None:
            return
        self.steps += 1
        self.faults += str(record.get("reason", "")).startswith("fault")
        self.requests += record.get("requester", "law") != "law"
        latency = record.get("latency_ms")
        if isinstance(latency, float) and math.isfinite(latency):
            self.latencies_ms.append(latency)
        self._log.write(json.dumps(_plain(record), allow_nan=False) + "\n")
        self._log.flush()

    def close(self, reason: str, error: str | None) -> None:
        """End the log; write the figure, ``run.json`` and ``README.txt`` (a disk that refuses them is
        said in the log, not raised: the tunnel is at zero already); give the folder up."""
        import logging

        log = logging.getLogger(__name__)
        if self._lock is None:
            return  # never opened: the run stopped before its loop (nothing was written)
        if self._log is not None:
            self._log.close()
            self._log = None
        try:
            from flagtrack.daemon.services.supervisor.control_figure import plot_control

            plot_control(read_control_log(self.run_dir / CONTROL_LOG), self.run_dir / FIGURE, self.about.get("law", ""))
        except (OSError, ValueError) as exc:
            log.error("supervisor: the control figure could not be written: %s", exc)
        try:
            self._write_description(_status(reason, error), reason, error)
        except OSError as exc:
            log.error("supervisor: run.json and README.txt could not be written: %s", exc)
        if self._lock is not None:
            self._lock.release()

    def _write_description(self, status: str, reason: str, error: str | None) -> None:
        run = self.description(status, reason, error)
        atomic_write(self.run_dir / RUN_JSON, json.dumps(run, indent=1, allow_nan=False) + "\n")
        atomic_write(self.run_dir / README, readme_text(run))

    def description(self, status: str, reason: str, error: str | None) -> dict[str, Any]:
        """The ``run.json`` object."""
        latencies = np.asarray(self.latencies_ms)
        return _plain(
            {
                "format": RUN_JSON_FORMAT,
                "format_version": RUN_JSON_VERSION,
                "run_id": self.run_dir.name,
                "flagtrack_version": __version__,
                "started_unix": self._started_unix,
                "started": _iso(self._started_unix),
                "command": command_line(),
                "status": status,
                "stop_reason": reason,
                "error": error,
                **self.about,
                "counts": {"steps": self.steps, "faults": self.faults, "requests": self.requests},
                "loop_latency_ms": {
                    "p50": float(np.percentile(latencies, 50)) if len(latencies) else None,
                    "p99": float(np.percentile(latencies, 99)) if len(latencies) else None,
                    "steps": len(latencies),
                },
                "files": [
                    {"path": name, "what": what, "bytes": (self.run_dir / name).stat().st_size}
                    for name, what in FILES
                    if (self.run_dir / name).is_file()
                ],
            }
        )


def readme_text(run: dict[str, Any]) -> str:
    """``README.txt`` of a control run, from its ``run.json`` object."""
    latency = run["loop_latency_ms"]
    lines = [
        f"Control run {run['run_id']}: a feedback-control experiment recorded by flagtrack {run['flagtrack_version']}",
        "",
        f"Started    {run['started'] or '?'}",
        f"Command    {run['command'] or '(not recorded)'}",
        f"Law        {run.get('law') or '(none: speed requests only)'}, every {run.get('period_s')} s",
        f"Status     {run['status']}" + (f" ({run['stop_reason']})" if run["stop_reason"] else ""),
        f"Steps      {run['counts']['steps']} ({run['counts']['faults']} faults, {run['counts']['requests']} requests)",
        f"Latency    p50 {_ms(latency['p50'])}, p99 {_ms(latency['p99'])} over {latency['steps']} steps (camera "
        "packet received to speed command written)",
        "",
        "Files",
    ]
    for item in run["files"]:
        lines += [f"  {item['path']}", f"      {item['what']}"]
    return "\n".join([*lines, ""])


def read_control_log(path: Path) -> list[dict[str, Any]]:
    """The records of a control log (a last line cut short by a crash is left out)."""
    records = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            records.append(json.loads(line))
        except ValueError:
            continue
    return records


def _status(reason: str, error: str | None) -> str:
    if error:
        return "error"
    return "finished" if reason == "finished" else "stopped"


def _plain(value: Any) -> Any:
    """``value`` with numbers that are not finite as None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} ms"


def _iso(t_unix: float) -> str | None:
    if not math.isfinite(t_unix):
        return None
    return time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(t_unix))
