"""``flagtrack reconstruct``: centrelines of a recorded flag, event file in, HDF5 out."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.commands._tracking_args import (
    add_tracking_arguments,
    apply_tracking_arguments,
    load_tracking_config_file,
)

if TYPE_CHECKING:
    from flagtrack.daemon.core.mapping import PointMapping
    from flagtrack.daemon.tracking_config import TrackingConfig

COMMAND = "reconstruct"
HELP = "reconstruct the centreline of the flag from an event file (HDF5 out)"
DESCRIPTION = """\
Track the flag's centreline through a recording with the chain of Raynaud & Mulleners (2024) and
write the smoothed centrelines, joints and Delta_RMS per update to an HDF5 file (docs/tracking.md).

Lengths are in the events' units: pixels (an event at (x, y) is the pixel whose centre is at (x, y))
or metres with a calibration; angles in degrees from +x towards +y; times in seconds on the
recording's clock (event t in us / 1e6). Flags override the config file's `tracker:` section.

example:
  flagtrack reconstruct run.raw -o run.h5 --root 102 240 --length 200 --tau 0.00025
"""

log = logging.getLogger(__name__)

_WRITE_EVERY = 8192  # updates buffered before an HDF5 append


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack reconstruct``."""
    parser.add_argument("file", type=Path, help="event file (.raw, .dat, .aedat4, .npy, .csv)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="output HDF5 file")
    parser.add_argument("-c", "--config", type=Path, help="YAML config with a `tracker:` section")
    add_tracking_arguments(parser)
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Reconstruct ``args.file`` into ``args.output``."""
    from flagtrack.daemon.tracking_config import TrackingConfig

    config = load_tracking_config_file(args.config) if args.config else TrackingConfig()
    config = apply_tracking_arguments(config, args)
    started = time.perf_counter()
    summary = reconstruct_file(args.file, args.output, config, config_path=str(args.config) if args.config else None,
                               progress=not args.no_progress and sys.stderr.isatty())
    elapsed = time.perf_counter() - started
    rate = summary["events_in"] / elapsed / 1e6 if elapsed > 0 else 0.0
    print(f"{summary['updates']} updates from {summary['events_in']} events "
          f"({summary['events_kept']} after denoising) in {elapsed:.2f} s ({rate:.1f} Mev/s) -> {args.output}",
          file=sys.stderr)
    return 0


def reconstruct_file(path: Path, output: Path, config: TrackingConfig, *, config_path: str | None = None,
                     progress: bool = False) -> dict[str, Any]:
    """Stream ``path`` through a :class:`~flagtrack.daemon.core.tracker.Tracker` into ``output``.

    Memory is bounded by the reader's chunk and the tracker's pending windows, not by the recording.

    Returns:
        A summary: updates, events_in, events_kept, first/last event times.
    """
    from flagtrack.daemon.core.centreline import CentrelineBatch
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.drivers.formats import open_events
    from flagtrack.drivers.formats.centreline import CentrelineWriter

    params = config.tracker_params(path=config_path)
    mapping = _load_mapping(config, config_path)
    units = "px" if mapping is None else getattr(mapping, "units", "m")
    with open_events(path) as reader:
        info = reader.info
        size = (info.width or 0, info.height or 0)
        tracker = Tracker(params, mapping=mapping, sensor_size=size)
        attrs = {**config.attrs(), "units": units, "input_file": str(path.resolve()), "input_format": info.format}
        if config.calibration is not None:
            from flagtrack.calibration import calibration_attrs

            attrs.update(calibration_attrs(config.calibration))
        with CentrelineWriter(output, tracker.s, params.chain.n_joints, attrs) as writer, \
                _progress_bar(path, progress) as bar:
            pending: list[CentrelineBatch] = []
            n_pending = 0
            for chunk in reader:
                batch = tracker.feed(chunk.events)
                if len(batch):
                    pending.append(batch)
                    n_pending += len(batch)
                if n_pending >= _WRITE_EVERY:
                    writer.append(CentrelineBatch.concatenate(pending))
                    pending, n_pending = [], 0
                bar(chunk.byte_offset)
            bar(path.stat().st_size)
            pending.append(tracker.finish())
            writer.append(CentrelineBatch.concatenate(pending))
            stats = tracker.stats
            writer.set_attrs({"events_in": stats.events_in, "events_kept": stats.events_kept})
    if stats.events_out_of_order:
        log.warning("%d events were out of time order", stats.events_out_of_order)
    return {"updates": stats.updates, "events_in": stats.events_in, "events_kept": stats.events_kept,
            "first_t_us": stats.first_t_us, "last_t_us": stats.last_t_us}


def _load_mapping(config: TrackingConfig, config_path: str | None) -> PointMapping | None:
    """The calibration mapping named by the config, or None for pixels."""
    if config.calibration is None:
        return None
    from flagtrack.daemon.errors import ConfigError

    try:
        from flagtrack.calibration import load_mapping  # type: ignore[attr-defined]
    except ImportError:
        raise ConfigError("calibration files need flagtrack.calibration.load_mapping, not available in this "
                          "version", key="tracker.calibration", path=config_path) from None
    return load_mapping(config.calibration)


class _progress_bar:
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

    def __enter__(self) -> _progress_bar:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
