"""``flagtrack reconstruct``: centrelines of a recorded flag, event file in, HDF5 out."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from flagtrack.daemon.commands._tracking_args import add_tracking_arguments, setup_from_arguments

if TYPE_CHECKING:
    from flagtrack.daemon.tracking.offline import ReconstructSummary
    from flagtrack.daemon.tracking.setup import TrackingSetup

COMMAND = "reconstruct"
EXIT_AT_ONCE = True  # the process ends when the file is written (no interpreter teardown: ~0.15 s)
HELP = "reconstruct the centreline of the flag from an event file (HDF5 out)"
DESCRIPTION = """\
Track the flag's centreline through a recording (Raynaud & Mulleners 2024) and write the smoothed
centrelines, joints and Delta_RMS per update to an HDF5 file. Lengths in the events' units (pixels,
or metres with --calibration); flags override the config's `tracker:` section.
More: docs/tracking.md, docs/commands.md.
"""

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack reconstruct``."""
    parser.add_argument("file", type=Path, help="event file (.raw, .dat, .aedat4, .npy, .csv)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="output HDF5 file")
    parser.add_argument("-c", "--config", type=Path, help="YAML config with a `tracker:` section")
    add_tracking_arguments(parser)
    parser.add_argument(
        "--strict",
        action="store_true",
        help="refuse a damaged recording (default: skip a corrupt stretch to the next valid time base, "
        "keep the rest and say what was skipped)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Reconstruct ``args.file`` into ``args.output``."""
    from flagtrack.daemon.tracking.offline import reconstruct_file
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import load_tracking_config_file

    check_paths(args.file, args.output, args.config)
    config = load_tracking_config_file(args.config) if args.config else TrackingConfig()
    setup = setup_from_arguments(config, args, path=str(args.config) if args.config else None)
    started = time.perf_counter()
    with _ProgressBar(args.file, not args.no_progress and sys.stderr.isatty()) as bar:
        output = args.output.resolve() if args.output.is_symlink() else args.output  # (written through a link)
        summary = reconstruct_file(  # (atomic: a failure leaves an earlier output as it was, and no stub)
            args.file, output, setup, progress=bar, strict=args.strict, check_sensor=_sensor_check(setup, args),
            atomic=True,
        )  # fmt: skip
    elapsed = time.perf_counter() - started
    rate = summary.events_in / elapsed / 1e6 if elapsed > 0 else 0.0
    print(
        f"{summary.updates} updates from {summary.events_in} events "
        f"({summary.events_kept} after denoising) in {elapsed:.2f} s ({rate:.1f} Mev/s) -> {args.output}",
        file=sys.stderr,
    )
    if summary.skipped_bytes:
        skipped = summary.skipped_bytes
        ranges = ", ".join(f"{a}-{b}" for a, b in skipped[:5])
        if len(skipped) > 5:
            ranges += f" and {len(skipped) - 5} more stretches up to byte {skipped[-1][1]}"
        print(
            f"{args.file}: damaged: skipped bytes {ranges} (at most {summary.events_lost_at_most} events lost; "
            "--strict refuses such a file)",
            file=sys.stderr,
        )
    print(f"{args.output}: {summary.verdicts()}", file=sys.stderr)
    if summary.updates == 0:  # (not the geometry: no window had a place to be)
        print(f"warning: {_why_no_updates(summary, setup.config.t_start_s, setup.config.t_stop_s)}", file=sys.stderr)
    elif summary.mostly_unmeasured:
        geometry = (
            "the calibration, --root, --length, --direction" if setup.mapping else "--root, --length, --direction"
        )
        print(
            f"warning: most updates found no flag: check the geometry first ({geometry}: where the flag is)",
            file=sys.stderr,
        )
    elif summary.reach is not None and (misfit := summary.reach.misfit(setup.params.chain.length, setup.units)):
        length = f"file {args.config}, key 'tracker.length'" if args.config and not args.length else "--length"
        print(f"warning: {misfit}: check {length} (and the root)", file=sys.stderr)
    return 0


def _why_no_updates(summary: ReconstructSummary, t_start_s: float | None, t_stop_s: float | None) -> str:
    """What to check when a recording gave no update at all."""
    if summary.events_in == 0:
        return "the recording holds no events"
    if summary.events_kept == 0:
        return f"the noise filter kept none of its {summary.events_in} events (tracker.denoise)"
    first_s, last_s = (summary.first_t_us or 0) * 1e-6, (summary.last_t_us or 0) * 1e-6
    events = f"the recording's events run from {first_s:.6g} s to {last_s:.6g} s"
    if t_stop_s is not None and t_stop_s < first_s:
        return f"--t-stop (tracker.t_stop_s) {t_stop_s:g} s is before its first event: {events}"
    if t_start_s is not None and t_start_s > last_s:
        return f"--t-start (tracker.t_start_s) {t_start_s:g} s is after its last event: {events}"
    span_s = last_s - first_s
    return (
        f"no window fits in the recording's {span_s:.3f} s of events: check --t-start, --t-stop "
        "(tracker.t_start_s, tracker.t_stop_s) and --tau"
    )


def check_paths(events: Path, output: Path, config: Path | None) -> None:
    """Refuse, before any work, an input or output the command cannot use (one line, exit 2); an
    earlier centreline file is replaced, any other file refused."""
    from flagtrack.daemon.commands._outputs import centrelines_file, check_output
    from flagtrack.daemon.errors import ConfigError

    for path in (events, config):
        if path is not None and path.is_dir():
            raise ConfigError(f"{path}: is a directory")
    if output.is_dir():
        raise ConfigError(f"-o {output}: is a directory (give the HDF5 file to write)")
    if not output.parent.is_dir():
        raise ConfigError(f"-o {output}: folder {output.parent} does not exist")
    if output.exists() and events.exists() and output.resolve() == events.resolve():
        raise ConfigError(f"-o {output}: is the event file itself (it would be overwritten)")
    if output.exists() and config is not None and config.exists() and output.resolve() == config.resolve():
        raise ConfigError(f"-o {output}: is the config file itself (it would be overwritten)")
    check_output(output, "-o", replaceable=centrelines_file, holds="flagtrack centrelines (HDF5)")


def _sensor_check(setup: TrackingSetup, args: argparse.Namespace) -> Callable[[int, int], None]:
    """Refuse a calibration made on another sensor than the recording's, and a root off that sensor
    (by the option or key that set it)."""
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.tracking.setup import calibration_misfit, root_on_sensor

    def check(width: int, height: int) -> None:
        misfit = calibration_misfit(setup.mapping, width, height, str(args.file))
        if misfit is not None:
            name = "--calibration" if args.calibration else f"file {args.config}, key 'tracker.calibration'"
            raise ConfigError(f"{name}: {setup.config.calibration}: {misfit}")
        if not root_on_sensor(setup, width, height):
            x, y = setup.params.chain.root
            name = "--root" if args.root else f"file {args.config}, key 'tracker.root'"
            plane = " (its outline mapped through the calibration)" if setup.mapping else ""
            raise ConfigError(f"{name}: ({x:g}, {y:g}) is off the {width} x {height} sensor{plane}")

    return check


class _ProgressBar:
    """A tqdm bar over the file's bytes when ``enabled`` (tqdm is imported only then)."""

    def __init__(self, path: Path, enabled: bool) -> None:
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=path.stat().st_size, unit="B", unit_scale=True, desc=path.name, leave=False)
        self._done = 0

    def __call__(self, byte_offset: int) -> None:
        if self._bar is not None and byte_offset > self._done:
            self._bar.update(byte_offset - self._done)
            self._done = byte_offset

    def __enter__(self) -> _ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
