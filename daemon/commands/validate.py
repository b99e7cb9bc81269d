"""``flagtrack validate RUN_DIR``: recompute a finished sweep's comparison with its point sensor."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from flagtrack.daemon.commands._tracking_args import add_tracking_arguments

if TYPE_CHECKING:  # imported where the command runs (fast --help)
    from flagtrack.daemon.sweep.runlog import RunRecord
    from flagtrack.daemon.tracking.setup import TrackingSetup

COMMAND = "validate"
HELP = "recompute the point-sensor comparison of a finished sweep (figures and table)"
DESCRIPTION = """\
Recompute a finished sweep's comparison with its point sensor: synchronise, compare with the
reconstruction at the sensor's x, and write RUN_DIR/validation/ (figures, validation.csv,
validation.png); the run log is not changed. More: docs/sensor.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack validate``."""
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a sweep's run folder")
    parser.add_argument("-o", "--out", type=Path, help="output folder (default RUN_DIR/validation)")
    parser.add_argument(
        "--centrelines",
        type=Path,
        metavar="DIR",
        help="use DIR/<point>_centrelines.h5 (or DIR/<point>.h5) instead of the run's centrelines",
    )
    parser.add_argument(
        "--reconstruct",
        action="store_true",
        help="reconstruct each raw file first, with the run's tracker section and the flags below",
    )
    parser.add_argument(
        "-c", "--config", type=Path, help="with --reconstruct: a YAML file whose tracker: section is used"
    )
    parser.add_argument(
        "--sync", choices=("auto", "trigger", "xcorr", "none"), help="clock sync mode (default: the run's)"
    )
    parser.add_argument("--x-over-l", type=float, metavar="F", help="beam position x/L (default: the run's)")
    parser.add_argument("--max-lag-ms", type=float, metavar="MS", help="cross-correlation search half-width")
    parser.add_argument("--window", type=float, default=0.3, metavar="S", help="time shown per point figure, s")
    parser.add_argument("--json", action="store_true", help="print one JSON object of the results")
    add_tracking_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Recompute, write the files, print the table."""
    import dataclasses

    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.sweep.runlog import RUN_LOG, read_run
    from flagtrack.daemon.validation.run import run_sensor_config, validate_run

    if not (args.run_dir / RUN_LOG).exists():
        raise ConfigError(f"no run log in {args.run_dir}", key="RUN_DIR")
    if args.centrelines is not None and not args.centrelines.is_dir():  # (every point "no centrelines file")
        raise ConfigError(f"{args.centrelines}: no such folder", key="--centrelines")
    for name, value in (("--x-over-l", args.x_over_l), ("--max-lag-ms", args.max_lag_ms), ("--window", args.window)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ConfigError(f"must be a positive number, got {value}", key=name)
    record = read_run(args.run_dir)
    sensor = run_sensor_config(record, str(args.run_dir / RUN_LOG))
    sync = dataclasses.replace(
        sensor.sync, **{k: v for k, v in (("mode", args.sync), ("max_lag_ms", args.max_lag_ms)) if v is not None}
    )
    beam = sensor.beam if args.x_over_l is None else dataclasses.replace(sensor.beam, x_over_l=args.x_over_l)
    sensor = dataclasses.replace(sensor, sync=sync, beam=beam)
    tracking = _tracking_setup(args, record) if args.reconstruct else None
    result = validate_run(
        args.run_dir,
        out_dir=args.out,
        centrelines_dir=args.centrelines,
        sensor=sensor,
        reconstruct=tracking,
        window_s=args.window,
    )
    rows = [_row(p) for p in result.points if p.sensor_status is not None]
    if args.json:
        print(
            json.dumps(
                {"csv": str(result.csv.resolve()), "figure": str(result.figure.resolve()), "points": rows},
                allow_nan=False,
            )
        )
    else:
        _print_table(rows)
        print(f"flagtrack validate: {len(rows)} points -> {result.csv} and {result.figure}", file=sys.stderr)
    damaged = [p.point_id for p in result.damaged]
    if damaged:
        print(f"flagtrack validate: {len(damaged)} point(s) not validated, their files damaged: "
              f"{', '.join(damaged)} (the lines above say which file)", file=sys.stderr)  # fmt: skip
    return 1 if damaged else 0


def _tracking_setup(args: argparse.Namespace, record: RunRecord) -> TrackingSetup:
    """The tracking set-up of ``--reconstruct``: the ``-c`` file's or the run's own, with the flags applied."""
    from flagtrack.daemon.commands._tracking_args import setup_from_arguments
    from flagtrack.daemon.validation.run import run_tracking_config

    config, where = run_tracking_config(record, args.config)
    return setup_from_arguments(config, args, path=where)  # (a flag's bad value named by its option)


_COLUMNS = (
    "point_id",
    "speed_mps",
    "state",
    "sensor_status",
    "sensor_sync",
    "sensor_offset_us",
    "sensor_offset_unc_us",
    "sensor_xcorr_offset_us",
    "sensor_error_rms_over_l",
    "sensor_error_max_over_l",
    "sensor_error_mean_over_l",
    "sensor_error_std_over_l",
    "cloud_distance_mean_over_l",
    "cloud_distance_std_over_l",
    "sensor_samples",
    "sensor_missing",
)


def _row(point) -> dict[str, object]:  # noqa: ANN001
    from flagtrack.daemon.sweep.quantities import POINT_ALIASES

    values = {name: getattr(point, name) for name in _COLUMNS}
    values.update({old: values[new] for old, new in POINT_ALIASES.items()})  # the keys before, same values
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in values.items()}


def _print_table(rows: list[dict[str, object]]) -> None:
    print(
        f"{'point':<16} {'U m/s':>6} {'state':<9} {'sync':<8} {'offset ms':>10} {'± us':>7} {'xcorr ms':>9} "
        f"{'e/L RMS %':>9} {'|e|/L max %':>11} {'Delta_RMS/L mean %':>18} {'missing':>8}  status"
    )
    for r in rows:
        print(
            f"{r['point_id']:<16} {r['speed_mps']:>6.2f} {r['state']:<9} {r['sensor_sync'] or '-':<8} "
            f"{_fmt(r['sensor_offset_us'], 1e-3, 3):>10} {_fmt(r['sensor_offset_unc_us'], 1, 1):>7} "
            f"{_fmt(r['sensor_xcorr_offset_us'], 1e-3, 3):>9} {_fmt(r['sensor_error_rms_over_l'], 100, 2):>9} "
            f"{_fmt(r['sensor_error_max_over_l'], 100, 2):>11} {_fmt(r['cloud_distance_mean_over_l'], 100, 2):>18} "
            f"{r['sensor_missing']:>8}  {r['sensor_status']}"
        )


def _fmt(value: object, scale: float, digits: int) -> str:
    return "-" if value is None else f"{float(value) * scale:.{digits}f}"  # type: ignore[arg-type]
