"""``flagtrack sensor -c rig.yaml``: run the point-sensor service alone: publish its samples on the bus."""

from __future__ import annotations

import argparse

from flagtrack.daemon.commands._service import add_service_arguments, run_one_service

COMMAND = "sensor"
HELP = "run the point sensor alone: publish its samples on the bus (docs/sensor.md)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack sensor``."""
    add_service_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the sensor service of the rig config until stopped."""
    return run_one_service("sensor", args)
