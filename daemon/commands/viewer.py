"""``flagtrack viewer -c rig.yaml``: run the Rerun viewer bridge alone."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "viewer"
HELP = "run the Rerun viewer bridge alone"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack viewer``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the viewer service of the rig config until stopped."""
    return run_one_service("viewer", args)
