"""``flagtrack <service> -c rig.yaml``: one service of the rig alone, one command per service of the
service table (camera, tracker, recorder, viewer, supervisor, sensor).

Each runs in its own process and reaches the others through the config's ``bus:`` section (several
hosts: see ``deploy/``); ``flagtrack up`` runs them together.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from flagtrack.daemon.commands._numbers import positive_seconds
from flagtrack.daemon.commands._registry import Command
from flagtrack.daemon.rig.table import SERVICES


def add_service_arguments(parser: argparse.ArgumentParser) -> None:
    """``-c rig.yaml`` and the shutdown timeout."""
    parser.add_argument("-c", "--config", type=Path, required=True, help="rig config (YAML)")
    parser.add_argument(
        "--shutdown-timeout", type=positive_seconds, default=10.0, help="seconds to wait for the service to stop"
    )


def run_one_service(name: str, args: argparse.Namespace) -> int:
    """Run service ``name`` of the rig config alone until it is stopped (or its work is done)."""
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.rig.run import run_rig

    # run_rig checks the files and folders of this service, before anything opens
    return run_rig(
        load_rig(args.config, services=()), [name], shutdown_timeout_s=args.shutdown_timeout, command="services"
    ).code


def _command(name: str, help_text: str) -> Command:
    return Command(name, help_text, add_service_arguments, lambda args: run_one_service(name, args))


COMMANDS = [_command(spec.name, spec.help) for spec in SERVICES]
