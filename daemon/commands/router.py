"""``flagtrack router``: a Zenoh router from Python (for hosts without ``zenohd``)."""

from __future__ import annotations

import argparse

COMMAND = "router"
HELP = "run a Zenoh router (joins camera and tracker hosts; same runtime as zenohd)"
DESCRIPTION = """\
Run the Zenoh runtime that eclipse-zenoh carries in router mode, listening on the given endpoints,
until Ctrl-C. Services on other hosts then use `bus: {mode: client, connect: [tcp/<router>:7447]}`
(see deploy/rig-camera-host.yaml and deploy/rig-tracker-host.yaml), or zenohd with
deploy/zenoh-router.json5 does the same job.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack router``."""
    parser.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                        help="endpoint to listen on (default tcp/0.0.0.0:7447); repeatable")
    parser.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                        help="another router to join; repeatable")


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted."""
    import signal
    import sys
    import threading

    from flagtrack.daemon.transport import Bus, BusConfig

    cfg = BusConfig(namespace="flagtrack", mode="router", listen=tuple(args.listen or ["tcp/0.0.0.0:7447"]),
                    connect=tuple(args.connect))
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with Bus(cfg):
        print(f"flagtrack router: listening on {', '.join(cfg.listen)}", file=sys.stderr, flush=True)
        stop.wait()
    print("flagtrack router: stopped", file=sys.stderr)
    return 0
