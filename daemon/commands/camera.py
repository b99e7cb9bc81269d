"""``flagtrack camera -c rig.yaml``: run the camera adapter alone: publish its event packets on the bus."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "camera"
HELP = "run the camera adapter alone: publish its event packets on the bus"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack camera``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the camera service of the rig config until stopped."""
    return run_one_service("camera", args)
