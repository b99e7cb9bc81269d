"""What a supervisor does when it starts in sweep mode: restart means resume.

A supervisor restarted after a crash (systemd's ``Restart=on-failure``, a power cut) must never
ramp the tunnel into a new sweep on its own. From the run folders alone:

- the configured run (``runs_dir/run_name``; without a name, the newest run of ``runs_dir``) was
  interrupted (its log has no stop record): **resume** it;
- it stopped for a reason (an error, a fault, a signal): **hold** (tunnel at zero), say why and how
  to resume it by hand;
- it finished: with a ``run_name``, **hold** (nothing left to do); without one, a **new** run;
- there is none: a **new** run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.sweep.runlog import RUN_LOG, RunRecord, read_run


@dataclass(frozen=True)
class StartDecision:
    """``action`` (``new``, ``resume``, ``hold``), the run folder it concerns (None for a new run
    without one) and why, in one line."""

    action: Literal["new", "resume", "hold"]
    run_dir: Path | None
    why: str


def start_decision(runs_dir: str | Path, run_name: str | None) -> StartDecision:
    """Decide from the run folders of ``runs_dir`` (see the module's rules)."""
    runs_dir = Path(runs_dir)
    run_dir = runs_dir / run_name if run_name else _newest_run(runs_dir)
    if run_dir is None or not (run_dir / RUN_LOG).exists():
        return StartDecision("new", run_dir, "no run to take up: a new run")
    try:
        record = read_run(run_dir)
    except FormatError as exc:
        return StartDecision("hold", run_dir, f"run {run_dir} cannot be read ({exc}); no new sweep started")
    done = sum(p.status == "done" for p in record.latest_points().values())
    if record.stop is None:
        return StartDecision(
            "resume",
            run_dir,
            f"resuming the interrupted run {run_dir} ({done} of {len(record.planned_ids)} points done)",
        )
    reason = str(record.stop.get("reason")) + (f": {record.stop['error']}" if record.stop.get("error") else "")
    if record.stop.get("reason") == "finished":
        if run_name:
            return StartDecision(
                "hold", run_dir, f"run {run_dir} is finished; nothing to do (set another supervisor.run_name)"
            )
        return StartDecision("new", None, f"the last run {run_dir} is finished: a new run")
    return StartDecision(
        "hold",
        run_dir,
        f"run {run_dir} stopped ({reason[:200]}); not resumed on its own: "
        f"flagtrack sweep --resume {run_dir} once the cause is fixed",
    )


def nothing_to_resume(record: RunRecord) -> str | None:
    """Why ``flagtrack sweep --resume`` has nothing to do with this run (it finished with every
    planned point done), or None: points are left to measure (or to measure again)."""
    if record.stop is None or record.stop.get("reason") != "finished":
        return None
    done = {pid for pid, p in record.latest_points().items() if p.status == "done"}
    planned = record.planned_ids
    if not set(planned) <= done:
        return None
    return f"run {record.run_dir} is finished ({len(planned)} of {len(planned)} points done); nothing to resume"


def _newest_run(runs_dir: Path) -> Path | None:
    """The run folder of ``runs_dir`` whose log was written last, or None."""
    try:
        logs = [(p.stat().st_mtime, p.parent) for p in runs_dir.glob(f"*/{RUN_LOG}")]
    except OSError:
        return None
    return max(logs)[1] if logs else None
