"""``flagtrack tunnel``: run a simulated tunnel, or set / read / stop the tunnel of a config."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flagtrack.drivers.tunnel.safe import SafeTunnel

COMMAND = "tunnel"
HELP = "wind tunnel: run a simulated one on a pty, or set/get/stop the one of a config"
DESCRIPTION = """\
Wind-tunnel utilities: `sim` runs a simulated tunnel on a pseudo-terminal; `get`, `set` and `stop`
read, set (ramped, verified, held until Ctrl-C) and stop the tunnel of -c rig.yaml (--port overrides
its port). More: docs/tunnel.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``sim``, ``get``, ``set`` and ``stop`` actions."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    sim = actions.add_parser(
        "sim",
        help="run a simulated tunnel on a pty and print its path",
        description="Run a simulated wind-tunnel controller on a pseudo-terminal and print its path, to try "
        "the tunnel commands and a rig without the tunnel (docs/tunnel.md).",
    )
    sim.add_argument("-c", "--config", help="rig config whose tunnel.sim / tunnel.modbus to use")
    sim.add_argument("--protocol", choices=("ascii", "modbus"), help="protocol (default: config or ascii)")
    sim.add_argument("--tau-s", type=float, help="time constant of the air speed, s")
    sim.add_argument("--watchdog-s", type=float, help="communication-loss watchdog, s")
    sim.add_argument("--ramp-mps2", type=float, help="the controller's own ramp limit, m/s^2")
    sim.add_argument("--initial-speed-mps", type=float, help="speed at start, m/s")
    for name, text in (
        ("get", "read speed and fault"),
        ("set", "ramp to a speed and hold it"),
        ("stop", "ramp to zero"),
    ):
        sub = actions.add_parser(
            name,
            help=text,
            description=f"{text[0].upper()}{text[1:]}, through the rig "
            "config's tunnel section and its safety limits (docs/tunnel.md).",
        )
        if name == "set":
            sub.add_argument("speed_mps", type=float, help="target speed, m/s")
            sub.add_argument(
                "--no-hold",
                action="store_true",
                help="exit once reached (the controller's watchdog then stops the fan)",
            )
        sub.add_argument("-c", "--config", required=True, help="rig config with a tunnel section")
        sub.add_argument("--port", help="override tunnel.port (and use it with the configured driver)")


def run(args: argparse.Namespace) -> int:
    """Dispatch to the chosen action."""
    return {"sim": _sim, "get": _get, "set": _set, "stop": _stop}[args.action](args)


def _config(args: argparse.Namespace, *, whole_file: bool = True) -> Any:
    """The tunnel section of ``-c``: the whole file checked (a typo anywhere is named, nothing opened),
    except for ``stop`` (``whole_file`` false), which a key outside the section never holds up."""
    import dataclasses

    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.drivers.tunnel.setup import TunnelConfig, load_tunnel_config

    cfg = TunnelConfig()
    if args.config and not whole_file:
        cfg = load_tunnel_config(args.config)
    elif args.config:
        rig_cfg = load_rig(args.config, services=())
        if rig_cfg.tunnel is None:
            raise ConfigError("section is missing", key="tunnel", path=str(args.config))
        cfg = rig_cfg.tunnel
    if getattr(args, "port", None):
        driver = cfg.driver if cfg.driver != "simulated" else cfg.sim.protocol
        cfg = dataclasses.replace(cfg, driver=driver, port=args.port)
    return cfg


class _Stopper:
    """First SIGINT/SIGTERM sets :attr:`event` (and calls ``on_first``); a second one forces exit."""

    def __init__(self, on_first: Any = None) -> None:
        self.event = threading.Event()
        self.on_first = on_first
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, frame: Any) -> None:
        if self.event.is_set():
            raise KeyboardInterrupt
        self.event.set()
        if self.on_first is not None:
            self.on_first()


def _sim(args: argparse.Namespace) -> int:
    import dataclasses

    from flagtrack.drivers.tunnel.simulated import SimulatedTunnel

    cfg = _config(args)
    overrides = {k: v for k, v in (("protocol", args.protocol), ("tau_s", args.tau_s), ("watchdog_s", args.watchdog_s),
                                   ("ramp_mps2", args.ramp_mps2), ("initial_speed_mps", args.initial_speed_mps))
                 if v is not None}  # fmt: skip
    params = dataclasses.replace(cfg.sim, **overrides)
    stopper = _Stopper()
    with SimulatedTunnel(params, cfg.modbus) as sim:
        print(sim.port, flush=True)
        print(f"simulated {params.protocol} tunnel on {sim.port} (tau {params.tau_s:g} s, watchdog "
              f"{params.watchdog_s:g} s); Ctrl-C to stop", file=sys.stderr, flush=True)  # fmt: skip
        last = ""
        while not stopper.event.wait(1.0):
            line = f"speed {sim.speed_mps:6.2f} m/s  set-point {sim.setpoint_mps:6.2f} m/s  fault {sim.fault or '-'}"
            if line != last and args.verbose:
                print(line, file=sys.stderr, flush=True)
            last = line
    return 0


def _get(args: argparse.Namespace) -> int:
    from flagtrack.drivers.tunnel.setup import open_tunnel

    tunnel = open_tunnel(_config(args))
    try:
        status = tunnel.status()
    finally:
        tunnel.close()
    if not status.link_ok:  # (it printed "speed nan m/s, fault no reply ..." on stdout, as a reading)
        from flagtrack.daemon.errors import DriverError

        raise DriverError(status.fault or "no reading", device=status.device)
    print(f"{status.device}: speed {status.speed_mps:.2f} m/s, fault {status.fault or 'none'}")
    return 0


def _set(args: argparse.Namespace) -> int:
    from flagtrack.drivers.tunnel.setup import open_tunnel

    tunnel = open_tunnel(_config(args))
    try:
        tunnel.check_setpoint(args.speed_mps)
    except BaseException:
        tunnel.close()
        raise
    stopper = _Stopper(on_first=tunnel.abort)
    if args.no_hold:
        try:
            tunnel.start()
            tunnel.set_speed_mps(args.speed_mps)
            print(f"{tunnel.device}: at {tunnel.read_speed_mps():.2f} m/s; exiting without keep-alive, "
                  f"the controller's watchdog ({tunnel.params.watchdog_s:g} s) will stop the fan")  # fmt: skip
        except BaseException:
            tunnel.safe_stop()
            raise
        finally:
            tunnel.close()
        return 0
    with tunnel:
        tunnel.set_speed_mps(args.speed_mps)
        print(f"{tunnel.device}: at {tunnel.read_speed_mps():.2f} m/s; holding (keep-alive every "
              f"{tunnel.params.keepalive_s:g} s), Ctrl-C or SIGTERM ramps to zero", flush=True)  # fmt: skip
        while not stopper.event.wait(1.0):
            _check_answering(tunnel)
            if args.verbose:
                print(f"speed {tunnel.read_speed_mps():.2f} m/s", file=sys.stderr, flush=True)
        started = time.monotonic()
    print(f"{tunnel.device}: ramped to zero in {time.monotonic() - started:.1f} s", flush=True)
    return 0


def _check_answering(tunnel: SafeTunnel) -> None:
    """Raise DriverError once the controller has not answered the keep-alive for longer than its
    watchdog (unplugged, powered off): it has stopped the fan, or nothing can now."""
    from flagtrack.daemon.errors import DriverError

    silent_s, why = tunnel.unanswered()
    if silent_s > tunnel.params.watchdog_s:
        raise DriverError(
            f"the controller has not answered for {silent_s:.0f} s ({why}); not holding any more: "
            f"its watchdog ({tunnel.params.watchdog_s:g} s) stops the fan",
            device=tunnel.device,
        )


def _stop(args: argparse.Namespace) -> int:
    from flagtrack.daemon.errors import DriverError, PortInUseError
    from flagtrack.drivers.tunnel.setup import open_tunnel

    try:
        tunnel = open_tunnel(_config(args, whole_file=False))
    except PortInUseError as exc:  # the owner keeps the port: the way to stop the tunnel now is to stop it
        raise DriverError(f"{exc}; to stop the tunnel, stop its owner (SIGTERM ramps the tunnel to zero)") from exc
    try:
        tunnel.safe_stop()
        speed = tunnel.read_speed_mps()
    finally:
        tunnel.close()
    print(f"{tunnel.device}: stopped, speed {speed:.2f} m/s")
    return 0
