"""``flagtrack sweep``: an unattended wind-speed sweep (whole rig in one process), or its resumption."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from flagtrack.daemon.commands._numbers import positive_seconds

COMMAND = "sweep"
HELP = "run a wind-speed sweep with the rig of -c rig.yaml, or resume one (--resume RUN_DIR)"
DESCRIPTION = """\
Run an unattended wind-speed sweep with the rig of -c rig.yaml (or resume one: --resume RUN_DIR):
each point of the plan is set, settled, recorded and logged to RUN_DIR/run.jsonl, then the summary,
figures and README.txt are written; whatever happens the tunnel ends ramped to zero.
Example: flagtrack sweep -c deploy/rig-sensor-sim.yaml. More: docs/tunnel.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack sweep``."""
    parser.add_argument("-c", "--config", type=Path, help="rig config with tunnel: and supervisor: sections")
    parser.add_argument("--resume", type=Path, metavar="RUN_DIR", help="resume this interrupted run")
    parser.add_argument("--runs-dir", type=Path, help="where run folders go (overrides supervisor.runs_dir)")
    parser.add_argument(
        "--shutdown-timeout", type=positive_seconds, default=90.0, help="seconds to wait for services to stop"
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines or bar, only the result")


def run(args: argparse.Namespace) -> int:
    """Run or resume the sweep; print where the results are."""
    import dataclasses

    from flagtrack.daemon.commands._progress import SweepProgressView
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import RigConfig, load_rig
    from flagtrack.daemon.rig.run import run_rig
    from flagtrack.daemon.sweep.restart import nothing_to_resume
    from flagtrack.daemon.sweep.runlock import held_by
    from flagtrack.daemon.sweep.runlog import read_run
    from flagtrack.daemon.typed_yaml import from_mapping

    if args.config is None and args.resume is None:
        raise ConfigError("give a rig config (-c rig.yaml) or a run to resume (--resume RUN_DIR)")
    if args.resume is not None and (holder := held_by(args.resume)) is not None:  # (before the rig starts)
        raise ConfigError(f"the run is in use by {holder}; not started", path=str(args.resume))
    if args.config is not None:
        rig = load_rig(args.config, services=())  # checked by run_rig once --runs-dir has changed it
    else:
        record = read_run(args.resume)
        if (why := nothing_to_resume(record)) is not None:  # the rig and the tunnel are left alone
            print(f"flagtrack sweep: {why}", file=sys.stderr)
            print(_run_files(args.resume), file=sys.stderr)
            return 0
        stored = dict(record.start.get("config", {}))
        stored.pop("sweep", None)
        stored.pop("path", None)
        rig = from_mapping(RigConfig, stored, path=str(args.resume / "run.jsonl"), key="config")
    if args.resume is None and rig.supervisor.sweep is None:
        raise ConfigError("needs a 'sweep:' plan", key="supervisor.sweep", path=str(args.config))
    try:
        supervisor = dataclasses.replace(
            rig.supervisor,
            mode="sweep",
            exit_when_done=True,
            runs_dir=args.runs_dir or rig.supervisor.runs_dir,
            resume_interrupted=False,  # a person starts this run (or names the one to resume)
        )
    except ValueError as exc:
        raise ConfigError(str(exc), key="supervisor", path=str(args.config or args.resume)) from exc
    rig = dataclasses.replace(rig, supervisor=supervisor)
    if args.resume is None and supervisor.run_name:
        _refuse_an_earlier_run(Path(supervisor.runs_dir) / supervisor.run_name, args.config)
    names = [*dict.fromkeys([*rig.services, "supervisor"])]
    with SweepProgressView(quiet=args.quiet) as progress:
        result = run_rig(
            rig,
            names,
            shutdown_timeout_s=args.shutdown_timeout,
            resume_dir=args.resume,
            quiet=args.quiet,
            on_supervisor_state=progress,
            command="sweep",
        )
    supervisor_service = result.service("supervisor")
    if supervisor_service is not None and supervisor_service.run_dir is not None:
        run_dir = supervisor_service.run_dir
        print(f"flagtrack sweep: {supervisor_service.stop_reason}; run folder {run_dir}", file=sys.stderr)
        print(_run_files(run_dir), file=sys.stderr)
        if supervisor_service.stop_reason != "finished":
            print(f"  resume with: flagtrack sweep --resume {run_dir}", file=sys.stderr)
            return result.code or 1
        return result.code
    # no run folder: the sweep never began (services that did not appear, a run in use): said, not 0
    print("flagtrack sweep: no run was started (the lines above say why)", file=sys.stderr)
    return result.code or 1


def _refuse_an_earlier_run(run_dir: Path, config: Path) -> None:
    """A new sweep into the folder of an earlier run (a fixed ``supervisor.run_name``): one line before
    the rig starts, saying whether to resume it or to name another run."""
    from flagtrack.daemon.errors import ConfigError, FormatError
    from flagtrack.daemon.sweep.restart import nothing_to_resume
    from flagtrack.daemon.sweep.runlock import held_by
    from flagtrack.daemon.sweep.runlog import RUN_LOG, read_run

    if not (run_dir / RUN_LOG).exists():
        return
    another = "set another supervisor.run_name (or --runs-dir)"
    if (holder := held_by(run_dir)) is not None:
        raise ConfigError(
            f"run {run_dir} is in use by {holder}: {another}", key="supervisor.run_name", path=str(config)
        )
    try:
        finished = nothing_to_resume(read_run(run_dir)) is not None
    except FormatError:
        finished = False
    if finished:
        raise ConfigError(
            f"run {run_dir} exists and is finished: {another}", key="supervisor.run_name", path=str(config)
        )
    raise ConfigError(
        f"run {run_dir} exists: resume it (flagtrack sweep --resume {run_dir}) or {another}",
        key="supervisor.run_name",
        path=str(config),
    )


def _found_line(run_dir: Path) -> str:
    """The onset and decay the run found and its points done, from its ``run.json`` ("" without one)."""
    import json

    from flagtrack.daemon.sweep.runfiles import speed_text

    try:
        run = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
        onset, decay, counts = run["onset_mps"], run["decay_mps"], run["counts"]
        done = f"{counts['done']} of {counts['planned']} points done"
    except (OSError, ValueError, KeyError, TypeError):
        return ""
    return f"  found   onset {speed_text(onset)} going up, decay {speed_text(decay)} coming down; {done}"


def _run_files(run_dir: Path) -> str:
    """Where the run's files are: those written, then those that are not (the lines above say why)."""
    files = [
        ("log", "run.jsonl", ""),
        ("summary", "summary.csv", ""),
        ("figure", "amplitude.png", ""),
        ("about", "README.txt", " (what each file is; run.json for programs)"),
    ]
    written = {name: (run_dir / name).exists() for _, name, _ in files}
    lines = [line] if (line := _found_line(run_dir)) else []
    lines += [f"  {label} {run_dir / name}{note}" for label, name, note in files if written[name]]
    missing = [name for name, there in written.items() if not there]
    if missing:
        lines.append(f"  not written: {', '.join(missing)} (the lines above say why)")
    return "\n".join(lines)
