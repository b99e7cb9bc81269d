"""Tracker options shared by ``flagtrack reconstruct`` and ``flagtrack up --replay``."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import TrackingSetup

log = logging.getLogger(__name__)

OPTIONS = {
    "root": ("root", "--root"),
    "length": ("length", "--length"),
    "direction_deg": ("direction", "--direction"),
    "joints": ("joints", "--joints"),
    "alpha": ("alpha", "--alpha"),
    "tau_s": ("tau", "--tau"),
    "dt_s": ("dt", "--dt"),
    "schedule[0]": ("tau", "--tau"),
    "ds": ("ds", "--ds"),
    "t_start_s": ("t_start", "--t-start"),
    "t_stop_s": ("t_stop", "--t-stop"),
    "calibration": ("calibration", "--calibration"),
}
"""``tracker:`` key -> (argparse destination, option) of the flags that set it."""


def add_tracking_arguments(parser: argparse.ArgumentParser) -> None:
    """The tracker flags; each overrides the config file's ``tracker:`` section."""
    parser.add_argument("--root", type=float, nargs=2, metavar=("X", "Y"), help="root of the flag")
    parser.add_argument("--length", type=float, metavar="L", help="flag length L")
    parser.add_argument("--direction", type=float, metavar="DEG", help="rest direction, degrees (default 0)")
    parser.add_argument("--joints", type=int, metavar="N", help="number of links N_j (default 10)")
    parser.add_argument("--alpha", type=float, metavar="A", help="search radius parameter (default 0.6)")
    parser.add_argument("--tau", type=float, metavar="S", help="update interval tau, s (default 0.00025)")
    parser.add_argument("--dt", type=float, metavar="S", help="time increment dt, s (default tau)")
    parser.add_argument("--ds", type=float, metavar="S", help="centreline step (default L/50)")
    parser.add_argument("--t-start", type=float, metavar="S", help="first update time, s")
    parser.add_argument("--t-stop", type=float, metavar="S", help="last update time, s")
    parser.add_argument("--method", choices=("robust", "paper"), help="robust (default) or the paper's update")
    parser.add_argument(
        "--calibration",
        type=Path,
        metavar="CAL.yaml",
        help="pixel -> metre calibration (flagtrack calibrate); outputs are then in metres",
    )


def apply_tracking_arguments(config: TrackingConfig, args: argparse.Namespace) -> TrackingConfig:
    """``config`` with the flags given on the command line applied."""
    from flagtrack.daemon.tracking.section import Method

    config = config.with_overrides(
        root=tuple(args.root) if args.root else None,
        length=args.length,
        direction_deg=args.direction,
        joints=args.joints,
        alpha=args.alpha,
        tau_s=args.tau,
        dt_s=args.dt,
        ds=args.ds,
        t_start_s=args.t_start,
        t_stop_s=args.t_stop,
        method=Method(args.method) if args.method else None,
        calibration=getattr(args, "calibration", None),
    )
    if (args.tau is not None or args.dt is not None) and config.schedule:
        log.warning("--tau/--dt given: the config's schedule is ignored")
        config = config.with_overrides(schedule=())
    return config


def setup_from_arguments(config: TrackingConfig, args: argparse.Namespace, *, path: str | None) -> TrackingSetup:
    """The checked tracking set-up of ``config`` with the flags applied; a value out of range that came
    from a flag is named by its option (``--joints: ...``), one from the file by its key.

    Raises:
        ConfigError: a value is missing or out of range.
    """
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.tracking.setup import tracking_setup

    try:
        return tracking_setup(apply_tracking_arguments(config, args), path=path)
    except ConfigError as exc:
        option = option_that_set(exc, args)
        if option is None:
            raise
        raise ConfigError(f"{option}: {exc.message if exc.key else exc}") from exc


def option_that_set(exc: ConfigError, args: argparse.Namespace) -> str | None:
    """The tracker flag (``--joints``) that gave the value ``exc`` refuses, or None when the value
    came from the config file (then its key names it)."""
    key = (exc.key or "").removeprefix("tracker.")
    if key == "t_start_s" and getattr(args, "t_stop", None) is not None and getattr(args, "t_start", None) is None:
        key = "t_stop_s"  # the flag given is the one to name
    dest, option = OPTIONS.get(key, (None, None))
    return option if dest is not None and getattr(args, dest, None) is not None else None
