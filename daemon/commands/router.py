"""``flagtrack router``: a Zenoh router from Python (for hosts without ``zenohd``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.commands._numbers import positive_seconds

if TYPE_CHECKING:  # zenoh is imported only when the router runs (fast --help)
    import threading

    from flagtrack.daemon.transport import Bus, BusConfig

COMMAND = "router"
HELP = "run a Zenoh router (joins camera and tracker hosts; same runtime as zenohd)"
DESCRIPTION = """\
Run a Zenoh router (eclipse-zenoh's runtime, as zenohd) that joins the rig's hosts, until Ctrl-C or
SIGTERM. With -c rig.yaml it listens where the rig's clients connect and takes the rig's
bus.security (TLS, access control); --zenohd-config prints the same router as a zenohd config.
More: docs/security.md, docs/commands.md.
"""
DEFAULT_PORT = 7447


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack router``."""
    parser.add_argument(
        "-c", "--config", type=Path, help="rig config whose bus.security (and namespace) the router takes"
    )
    parser.add_argument(
        "--listen",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to listen on; repeatable (default: with -c, the rig's bus.connect when its services "
        "are clients of this router, or its bus.listen in router mode; else "
        f"tcp/127.0.0.1:{DEFAULT_PORT}, tls/... on a secured bus)",
    )
    parser.add_argument(
        "--connect", action="append", default=[], metavar="ENDPOINT", help="another router to join; repeatable"
    )
    parser.add_argument(
        "--shutdown-timeout", type=positive_seconds, default=10.0, help="seconds to wait for the router to close"
    )
    parser.add_argument(
        "--zenohd-config", action="store_true", help="print this router as a zenohd config (JSON5) and exit"
    )
    parser.add_argument("--rules", action="store_true", help="print the access-control rules, one per line, and exit")


class RouterService:
    """The router's session as a service: serves until stopped, then closes the session in its own thread
    (so a second signal still reaches the main thread if closing hangs)."""

    name = "router"

    def __init__(self, bus: Bus, ready_line: str) -> None:
        self.bus, self.ready_line = bus, ready_line

    def start(self) -> None:
        """Say it listens: once the signals are handled (a script that signals on this line stops it
        cleanly). Nothing to open: the session is the caller's (opened first: a busy port is one line)."""
        print(self.ready_line, file=sys.stderr, flush=True)

    def run(self, stop: threading.Event) -> None:
        from flagtrack.daemon.services.sd_notify import beat

        try:
            while not stop.wait(0.5):  # the router's work runs in Zenoh's threads; this loop only serves
                beat(self.name, "serving")
        finally:
            self.bus.close()


def router_config(args: argparse.Namespace) -> BusConfig:
    """The router's bus: the rig's namespace, security and rules (with ``-c``), the endpoints asked for.

    Raises:
        ConfigError: a bad rig file, or endpoints a secured bus does not take (naming the key).
    """
    import dataclasses

    from flagtrack.daemon.security.config import ROUTER
    from flagtrack.daemon.transport import BusConfig

    if args.config is None:
        listen = tuple(args.listen or [f"tcp/127.0.0.1:{DEFAULT_PORT}"])
        return BusConfig(namespace="flagtrack", mode="router", listen=listen, connect=tuple(args.connect))
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import load_rig

    rig = load_rig(args.config, services=())
    bus = rig.bus_config_for([], identity=ROUTER)
    scheme = "tls" if bus.secured else "tcp"
    rig_endpoints = bus.listen if bus.mode == "router" else bus.connect if bus.mode == "client" else ()
    listen = tuple(args.listen) or rig_endpoints or (f"{scheme}/127.0.0.1:{DEFAULT_PORT}",)
    try:
        return dataclasses.replace(bus, mode="router", listen=listen, connect=tuple(args.connect))
    except ConfigError as exc:  # an endpoint of the command line
        raise ConfigError(str(exc).split(": ", 1)[-1], key="--listen/--connect", path=str(args.config)) from None


def zenohd_config(settings: dict[str, Any]) -> dict[str, Any]:
    """Zenoh settings (path -> value) as the nested object of a zenohd config file."""
    config: dict[str, Any] = {}
    for path, value in settings.items():
        node = config
        *parents, last = path.split("/")
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = value
    return config


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted: the first SIGINT/SIGTERM closes gracefully, a second forces (runner.py)."""
    import json

    from flagtrack.daemon.security.config import REDACTED
    from flagtrack.daemon.services.runner import run_services
    from flagtrack.daemon.transport import Bus, zenoh_settings

    cfg = router_config(args)
    if args.zenohd_config:
        head = "// zenohd -c THIS_FILE: the router of"
        print(f"{head} {args.config or 'flagtrack router'} (made by flagtrack router --zenohd-config)")
        settings = zenoh_settings(cfg, check_files=False)
        if "password" in settings.get("transport/auth/usrpwd", {}):  # not printed: put it in by hand
            settings["transport/auth/usrpwd"]["password"] = REDACTED
        print(json.dumps(zenohd_config(settings), indent=2))
        return 0
    if args.rules:
        from flagtrack.daemon.security.acl import describe

        if cfg.access_control is None:
            print("no access control (bus.security.acl is off): every peer may do everything", file=sys.stderr)
            return 0
        print("\n".join(describe(cfg.access_control)))
        return 0
    bus = Bus(cfg)  # a bad endpoint or a busy port: one clear line (ConfigError), before any signal handling
    what = " (mutual TLS" + (", access control" if cfg.access_control else "") + ")" if cfg.secured else ""
    ready = f"flagtrack router: listening on {', '.join(cfg.listen)}{what}"
    report = run_services([RouterService(bus, ready)], shutdown_timeout_s=args.shutdown_timeout)
    if report.abandoned:
        print(f"flagtrack router: did not close within {args.shutdown_timeout:g} s", file=sys.stderr)
        return 1
    for exc in report.errors.values():
        print(f"flagtrack router: failed: {exc}", file=sys.stderr)
        return 1
    print("flagtrack router: stopped", file=sys.stderr)
    return 0
