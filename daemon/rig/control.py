"""A rig set up for a control experiment (``flagtrack control``, ``bench control``, ``demo --feedback``):
the supervisor in mode ``control`` with the law asked for, and the services the loop needs."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.services.supervisor.laws import BUILT_IN, law_file

NO_LAW = "none"
"""``--controller none``: no law, the speed moves on requests from the bus only."""

LOOP_SERVICES = ("flagstate", "supervisor")
"""Services every control run needs beside the rig's own (the recorder too when the run is recorded)."""


def control_rig(
    rig: RigConfig,
    controller: str | None,
    *,
    duration_s: float | None = None,
    period_s: float | None = None,
    out: Path | None = None,
) -> tuple[RigConfig, list[str]]:
    """``rig`` with its supervisor in mode ``control`` running ``controller`` (None: the one of
    ``supervisor.control.controller``), for ``duration_s`` and ``period_s`` when given, its run folder
    ``out`` when given; and the services to run.

    Raises:
        ConfigError: no law, a law file that is not there, a run folder that holds a run, a bad
            value (each naming its option or key).
    """
    control = rig.supervisor.control
    law = controller if controller is not None else control.controller
    key = "--controller" if controller is not None else "supervisor.control.controller"
    where = rig.path if key != "--controller" else None  # (an option is named alone, a key with its file)
    if law is None:
        raise ConfigError(
            f"no control law: give --controller FILE.py:FUNCTION, {', '.join(BUILT_IN)}, or {NO_LAW} (speed "
            "requests only)",
            key="--controller",
            path=rig.path,
        )
    if law == NO_LAW:
        if not control.requests:
            raise ConfigError(
                f"{NO_LAW}: no law and supervisor.control.requests false: nothing would move the speed",
                key=key,
                path=where,
            )
    elif law not in BUILT_IN:
        law_file(law, key=key, path=where)
    supervisor = rig.supervisor
    runs_dir, run_name = supervisor.runs_dir, supervisor.run_name
    if out is not None:
        out = out.expanduser().resolve()
        if (out / "control.jsonl").exists():
            raise ConfigError(f"{out} holds a control run already; choose another folder", key="--out")
        runs_dir, run_name = out.parent, out.name
    changes = {"controller": None if law == NO_LAW else law}
    if duration_s is not None:
        changes["duration_s"] = duration_s  # type: ignore[assignment]
    if period_s is not None:
        changes["period_s"] = period_s  # type: ignore[assignment]
    try:
        control = dataclasses.replace(control, **changes)  # type: ignore[arg-type]
        required = tuple(dict.fromkeys([*supervisor.required, "flagstate"]))
        supervisor = dataclasses.replace(
            supervisor,
            mode="control",
            control=control,
            exit_when_done=True,
            runs_dir=runs_dir,
            run_name=run_name,
            required=required if control.record else tuple(r for r in required if r != "recorder"),
        )
    except ValueError as exc:
        raise ConfigError(str(exc), key="--duration/--period", path=rig.path) from exc
    rig = dataclasses.replace(rig, supervisor=supervisor)
    extra = (*LOOP_SERVICES, "recorder") if control.record else LOOP_SERVICES
    return rig, [*dict.fromkeys([*rig.services, *extra])]
