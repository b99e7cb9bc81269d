"""``flagtrack recorder -c rig.yaml``: run the recorder alone: camera packets to .raw files on command."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "recorder"
HELP = "run the recorder alone: camera packets to .raw files on command"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack recorder``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the recorder service of the rig config until stopped."""
    return run_one_service("recorder", args)
