"""``flagtrack tracker -c rig.yaml``: run the live tracker alone: camera packets in, centrelines out."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "tracker"
HELP = "run the live tracker alone: camera packets in, centrelines out"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack tracker``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the tracker service of the rig config until stopped."""
    return run_one_service("tracker", args)
