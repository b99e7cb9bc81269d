"""``flagtrack router``: a Zenoh router from Python (for hosts without ``zenohd``)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # zenoh is imported only when the router runs (fast --help)
    import threading

    from flagtrack.daemon.transport import Bus

COMMAND = "router"
HELP = "run a Zenoh router (joins camera and tracker hosts; same runtime as zenohd)"
DESCRIPTION = """\
Run the Zenoh runtime that eclipse-zenoh carries in router mode, listening on the given endpoints,
until Ctrl-C (or SIGTERM). Services on other hosts then use `bus: {mode: client, connect: [tcp/<router>:7447]}`
(see deploy/rig-camera-host.yaml and deploy/rig-tracker-host.yaml), or zenohd with
deploy/zenoh-router.json5 does the same job. The first signal closes the router gracefully, a
second one forces the process out (exit 130), as for the other services.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack router``."""
    parser.add_argument(
        "--listen",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to listen on (default tcp/0.0.0.0:7447); repeatable",
    )
    parser.add_argument(
        "--connect", action="append", default=[], metavar="ENDPOINT", help="another router to join; repeatable"
    )
    parser.add_argument("--shutdown-timeout", type=float, default=10.0, help="seconds to wait for the router to close")


class RouterService:
    """The router's session as a service: serves until stopped, then closes the session in its own thread
    (so a second signal still reaches the main thread if closing hangs)."""

    name = "router"

    def __init__(self, bus: Bus) -> None:
        self.bus = bus

    def run(self, stop: threading.Event) -> None:
        try:
            stop.wait()
        finally:
            self.bus.close()


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted: the first SIGINT/SIGTERM closes gracefully, a second forces (runner.py)."""
    import sys

    from flagtrack.daemon.services.runner import run_services
    from flagtrack.daemon.transport import Bus, BusConfig

    cfg = BusConfig(
        namespace="flagtrack",
        mode="router",
        listen=tuple(args.listen or ["tcp/0.0.0.0:7447"]),
        connect=tuple(args.connect),
    )
    bus = Bus(cfg)  # a bad endpoint or a busy port: one clear line (ConfigError), before any signal handling
    print(f"flagtrack router: listening on {', '.join(cfg.listen)}", file=sys.stderr, flush=True)
    report = run_services([RouterService(bus)], shutdown_timeout_s=args.shutdown_timeout)
    if report.abandoned:
        print(f"flagtrack router: did not close within {args.shutdown_timeout:g} s", file=sys.stderr)
        return 1
    for exc in report.errors.values():
        print(f"flagtrack router: failed: {exc}", file=sys.stderr)
        return 1
    print("flagtrack router: stopped", file=sys.stderr)
    return 0
