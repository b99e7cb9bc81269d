"""``flagtrack up``: run the rig's services in one process (Zenoh peer on loopback by default)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from flagtrack.daemon.commands._numbers import positive_seconds
from flagtrack.daemon.commands._tracking_args import add_tracking_arguments, option_that_set

if TYPE_CHECKING:
    from flagtrack.daemon.rig.config import RigConfig

COMMAND = "up"
HELP = "run the rig's services in one process (-c rig.yaml), or replay a file through them (--replay)"
DESCRIPTION = """\
Run the rig's services (the config's `services:`) in one process over Zenoh, or replay a recording
through camera -> Zenoh -> tracker (--replay: the results of `flagtrack reconstruct`). The first
Ctrl-C stops gracefully, a second one forces. More: docs/live.md, docs/commands.md.
"""

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack up``."""
    parser.add_argument("-c", "--config", type=Path, help="rig config (YAML)")
    parser.add_argument("--replay", type=Path, metavar="FILE", help="replay this recording as the camera")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed factor (0: as fast as possible)")
    parser.add_argument("--loop", action="store_true", help="replay in a loop")
    parser.add_argument("--exit-at-eof", action="store_true", help="stop when the replayed file ends")
    parser.add_argument("--centrelines", type=Path, metavar="OUT.h5", help="write the centrelines to this file")
    parser.add_argument("--rrd", type=Path, metavar="OUT.rrd", help="write the Rerun view to this file (headless)")
    parser.add_argument(
        "--record",
        type=Path,
        metavar="BASE",
        help="record the camera to BASE.raw (+ .json) in the recorder's folder (recordings/ by default)",
    )
    parser.add_argument(
        "--shutdown-timeout", type=positive_seconds, default=10.0, help="seconds to wait for services to stop"
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress or status lines (errors still print)")
    add_tracking_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Build the rig from the config and flags, run it, report."""
    from flagtrack.daemon.commands._progress import SweepProgressView
    from flagtrack.daemon.commands._recording_view import RecordingView
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.run import run_rig

    rig, names = rig_from_args(args)
    _refuse_outputs_over_inputs(args, rig)
    sweeping = "supervisor" in names  # (its points are recorded: the sweep's lines say so)
    try:
        with (
            SweepProgressView(quiet=args.quiet or not sweeping) as progress,
            RecordingView(quiet=args.quiet or sweeping) as recording,
        ):
            result = run_rig(
                rig,
                names,
                exit_at_end_of_stream=args.exit_at_eof,
                centrelines=args.centrelines,
                shutdown_timeout_s=args.shutdown_timeout,
                quiet=args.quiet,
                on_supervisor_state=progress,
                on_services=recording,
            )
    except ConfigError as exc:  # a value the command line gave is named as such, not as the file's key
        option = option_that_set(exc, args)
        if exc.key == "camera.replay.path" and args.replay is not None:  # (a file that is no recording)
            option = "--replay"
        if option is not None:
            raise ConfigError(exc.message, key=option) from None
        raise
    recorder = result.service("recorder")
    if "supervisor" not in names and recorder is not None and recorder.failure:  # (a sweep says it itself)
        print(f"flagtrack up: {recorder.failure}", file=sys.stderr)
        return result.code or 1
    return result.code


def _refuse_outputs_over_inputs(args: argparse.Namespace, rig: RigConfig) -> None:
    """``--centrelines`` or ``--rrd`` naming the recording, the rig config or the calibration (the
    folders are checked with the rig's), or ``--record`` naming a recording made before."""
    from flagtrack.daemon.commands._outputs import RRD, centrelines_file, check_output

    inputs = (args.replay, args.config, rig.tracker.calibration)
    if args.centrelines is not None:
        holds = "flagtrack centrelines (HDF5)"
        check_output(
            args.centrelines, "--centrelines", inputs, replaceable=centrelines_file, holds=holds, makes_folder=True
        )
    if args.rrd is not None:
        check_output(args.rrd, "--rrd", inputs, replaceable=RRD, holds="a Rerun view (.rrd)", makes_folder=True)
    if args.record is not None:  # a second `up --record NAME` replaced the first recording without a word
        from flagtrack.daemon.errors import ConfigError
        from flagtrack.daemon.services.recorder import recording_base

        base = recording_base(rig.recorder.directory, str(args.record))
        earlier = base.with_name(base.name + ".raw")
        if earlier.exists():
            raise ConfigError(
                f"{earlier} exists: give another name, or move it (a recording is not replaced)", key="--record"
            )


def rig_from_args(args: argparse.Namespace) -> tuple[RigConfig, list[str]]:
    """The rig config of ``-c`` with the command-line overrides applied; the services to run."""
    import dataclasses

    from flagtrack.daemon.commands._tracking_args import apply_tracking_arguments
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import CameraConfig, RigConfig, load_rig
    from flagtrack.drivers.camera.replay import ReplayConfig

    if args.config is None and args.replay is None:
        raise ConfigError("give a rig config (-c rig.yaml) or a recording to replay (--replay FILE)")
    # files and folders are checked by run_rig, once the flags below have changed the rig
    rig = load_rig(args.config, services=()) if args.config else RigConfig(services=("camera", "tracker"))
    names = list(rig.services)
    if args.replay is not None:
        if not args.replay.is_file():
            what = "is a directory, not a recording" if args.replay.is_dir() else "no such recording"
            raise ConfigError(f"{args.replay}: {what}", key="--replay")
        camera = CameraConfig(
            id=rig.camera.id,
            adapter="replay",
            packet_us=rig.camera.packet_us,
            replay=ReplayConfig(args.replay, speed=args.speed, loop=args.loop),
        )
        rig = dataclasses.replace(rig, camera=camera)
        for name in ("camera", "tracker"):
            if name not in names:
                names.append(name)
    rig = dataclasses.replace(rig, tracker=apply_tracking_arguments(rig.tracker, args))
    if args.rrd is not None:
        rig = dataclasses.replace(rig, viewer=dataclasses.replace(rig.viewer, sink="rrd", rrd_path=args.rrd))
        if "viewer" not in names:
            names.append("viewer")
    if args.record is not None:
        rig = dataclasses.replace(rig, recorder=dataclasses.replace(rig.recorder, path=str(args.record)))
        if "recorder" not in names:
            names.append("recorder")
    return rig, names
