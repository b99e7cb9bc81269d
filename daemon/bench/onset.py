"""``flagtrack bench onset``: how the onset detector's defaults score on synthetic event-rate traces
(false alarms per hour, missed detections, onset and decay delays; docs/tunnel.md)."""

from __future__ import annotations

import argparse

COMMAND = "onset"
HELP = "false alarms and delays of the flag-state detector on synthetic event-rate traces (about a minute)"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack bench onset``."""
    parser.add_argument("--hours", type=float, default=20.0, help="hours of still traces for false alarms")
    parser.add_argument("--trials", type=int, default=40, help="onset/decay trials per flapping ratio")
    parser.add_argument("--grid", action="store_true", help="also score the parameter variants of GRID")


def run(args: argparse.Namespace) -> int:
    """Print the measurement table (and the grid with ``--grid``)."""
    from flagtrack.daemon.bench.onset_traces import GRID, report
    from flagtrack.daemon.core.onset import OnsetParams

    variants = GRID if args.grid else {"defaults": OnsetParams()}
    for name, params in variants.items():
        print(f"== {name}: {params}")
        for row in report(params, args.hours, args.trials):
            print(row)
    return 0
