"""``flagtrack bench ...``: speed, memory and accuracy benchmarks (one module each in flagtrack.daemon.bench)."""

from __future__ import annotations

import argparse

COMMAND = "bench"
HELP = "run a benchmark (decode, reconstruct, accuracy, live, ...) and print its figures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add one sub-subcommand per benchmark module."""
    from flagtrack.daemon import bench
    from flagtrack.daemon.commands._registry import add_subcommands

    add_subcommands(parser, bench, "bench")


def run(args: argparse.Namespace) -> int:  # noqa: ARG001  # pragma: no cover - each benchmark sets its own run
    raise SystemExit("flagtrack bench: choose a benchmark")
