"""A simulated wind tunnel on a real pseudo-terminal.

It opens a pty pair, gives the client side's path (:attr:`SimulatedTunnel.port`, e.g.
``/dev/pts/7``) to whoever wants to drive it, and answers on the other side from a thread, in the
default ASCII protocol or as a Modbus RTU drive, with first-order speed dynamics, its own ramp
limit and a communication-loss watchdog (see :mod:`.sim_model`). Its current speed is readable
in-process (:attr:`SimulatedTunnel.speed_mps`) so the simulated camera can follow it.

Fault injection for tests (:meth:`SimulatedTunnel.inject`): ``mute`` (the link is cut: nothing is
processed or answered, so the watchdog trips), ``stall_mps`` (the fan cannot go faster),
``garbage`` (commands are executed but replies are corrupted) and ``fault`` (the controller reports
a fault, e.g. ``OVERCURRENT``, through its fault query, as a drive's fault bit).
"""

from __future__ import annotations

import logging
import threading
import time
from types import TracebackType

from flagtrack.drivers.serial.pty_link import PtyLink
from flagtrack.drivers.tunnel.modbus import ModbusMap
from flagtrack.drivers.tunnel.sim_model import SimParams, TunnelModel
from flagtrack.drivers.tunnel.sim_responders import AsciiResponder, ModbusResponder, Responder

log = logging.getLogger(__name__)

GARBAGE_LINE = b"\x15#?garbled reply!\n"


class SimulatedTunnel:
    """A simulated tunnel answering on a pseudo-terminal from a background thread.

    Args:
        params: dynamics, watchdog and protocol.
        modbus_map: register map, when ``params.protocol`` is ``modbus``.

    Use as a context manager, or call :meth:`start` and :meth:`close`.
    """

    def __init__(self, params: SimParams = SimParams(), modbus_map: ModbusMap = ModbusMap()) -> None:
        self.params = params
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._model = TunnelModel(params, time.monotonic())
        self._responder: Responder = (
            ModbusResponder(self._model, modbus_map) if params.protocol == "modbus" else AsciiResponder(self._model)
        )
        self._mute = False
        self._garbage = False
        self._link = PtyLink()
        self.port = self._link.port
        self._thread = threading.Thread(target=self._serve, name=f"simulated tunnel {self.port}", daemon=True)

    def start(self) -> SimulatedTunnel:
        """Start answering; return self."""
        if not self._thread.is_alive():
            self._thread.start()
            log.info("simulated %s tunnel on %s", self.params.protocol, self.port)
        return self

    @property
    def speed_mps(self) -> float:
        """Current air speed, m/s (thread-safe)."""
        with self._lock:
            self._model.advance(time.monotonic())
            return self._model.speed_mps

    @property
    def setpoint_mps(self) -> float:
        """Set-point last accepted by the controller, m/s (0 after a stop or a watchdog trip)."""
        with self._lock:
            return self._model.setpoint_mps if self._model.running else 0.0

    @property
    def fault(self) -> str | None:
        """The controller's fault (``WATCHDOG`` after a trip), ``None`` when healthy."""
        with self._lock:
            return self._model.fault

    @property
    def watchdog_trips(self) -> int:
        """How many times the watchdog brought the tunnel to zero."""
        with self._lock:
            return self._model.watchdog_trips

    @property
    def valid_commands(self) -> int:
        """Valid commands received so far."""
        with self._lock:
            return self._model.valid_commands

    def inject(
        self,
        *,
        mute: bool | None = None,
        stall_mps: float | None = None,
        garbage: bool | None = None,
        fault: str | None = None,
    ) -> None:
        """Switch faults on or off (arguments left ``None`` are unchanged; ``clear_faults`` resets)."""
        with self._lock:
            if fault is not None:
                self._model.fault = fault
            if mute is not None:
                self._mute = mute
            if stall_mps is not None:
                self._model.stall_mps = stall_mps
            if garbage is not None:
                self._garbage = garbage

    def clear_faults(self) -> None:
        """Remove every injected fault."""
        with self._lock:
            self._mute, self._garbage, self._model.stall_mps, self._model.fault = False, False, None, None

    def close(self) -> None:
        """Stop the thread and close both ends of the pty (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._link.close()

    def __enter__(self) -> SimulatedTunnel:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            ready = self._link.wait_readable(self.params.tick_s)
            if ready is None:
                return
            data = self._link.read(self.params.tick_s) if ready else b""
            with self._lock:
                now_s = time.monotonic()
                self._model.advance(now_s)
                if self._mute:
                    continue
                reply = self._responder.feed(data, now_s)
                if reply and self._garbage:
                    reply = GARBAGE_LINE if self.params.protocol == "ascii" else bytes(b ^ 0x5A for b in reply)
            if reply:
                self._link.write(reply)
