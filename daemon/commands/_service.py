"""What the one-service commands (``flagtrack camera|tracker|recorder|viewer|supervisor``) share."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_service_arguments(parser: argparse.ArgumentParser) -> None:
    """``-c rig.yaml`` and the shutdown timeout."""
    parser.add_argument("-c", "--config", type=Path, required=True, help="rig config (YAML)")
    parser.add_argument("--shutdown-timeout", type=float, default=10.0, help="seconds to wait for the service to stop")


def run_one_service(name: str, args: argparse.Namespace) -> int:
    """Run service ``name`` of the rig config alone (its bus section says how to reach the others)."""
    from flagtrack.daemon.commands.up import run_rig
    from flagtrack.daemon.rig import load_rig

    rig = load_rig(args.config)
    return run_rig(rig, [name], shutdown_timeout_s=args.shutdown_timeout).code
