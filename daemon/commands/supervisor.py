"""``flagtrack supervisor -c rig.yaml``: run the supervisor alone (it owns the wind tunnel)."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "supervisor"
HELP = "run the supervisor alone: tunnel, flag state from event rates, sweeps or feedback"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack supervisor``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the supervisor of the rig config until its work is done or it is stopped."""
    return run_one_service("supervisor", args)
