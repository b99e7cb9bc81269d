"""The flag-state service: the flag's state cycle by cycle, from the tracker's centrelines.

Subscribes to the centrelines and the tunnel's state; each centreline message goes through a
:class:`~flagtrack.daemon.core.flagstate.FlagStateTracker` (the pure core, with the functions of the
sweep's per-point figures), and every state it makes is published as a
:class:`~flagtrack.daemon.schema.FlagState` on ``<ns>/flag/state``, with the tunnel's last speed
readback and the reception time of the camera packet behind it (for the control loop's latency).
"""

from __future__ import annotations

import logging
import math
import threading
import time

import numpy as np

from flagtrack.daemon.core.flagstate import CycleState, FlagStateTracker, StateParams
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, FlagState, TunnelState
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus, Publisher, Subscription

log = logging.getLogger(__name__)


class FlagStateService:
    """Publishes the flag's state from the centrelines until stopped (see the module).

    Args:
        bus: the bus.
        params: the core's parameters (the flag's frame, the section's settings).
        camera_id: the camera whose centrelines these are (the states' ``source``).
    """

    name = "flagstate"

    def __init__(self, bus: Bus, params: StateParams, camera_id: str) -> None:
        self.bus, self.params, self.camera_id = bus, params, camera_id
        self.published = 0
        self._lines: Subscription | None = None
        self._tunnel: Subscription | None = None
        self._publisher: Publisher | None = None
        self._speed_mps = -1.0
        self._problems = ProblemLog(log, "flagstate")

    def start(self) -> None:
        """Subscribe to the centrelines and the tunnel's state; declare the state's publisher."""
        keys = self.bus.keys
        self._lines = self.bus.subscribe(keys.centrelines(), CentrelineMessage, capacity=10_000, max_bytes=64 << 20)
        self._tunnel = self.bus.subscribe(keys.tunnel_state(), TunnelState, capacity=16, ring=True)
        self._publisher = self.bus.publisher(keys.flag_state(), express=True)

    def run(self, stop: threading.Event) -> None:
        lines, publisher = self._lines, self._publisher
        if lines is None or publisher is None:
            raise RuntimeError("flagstate: start() first")
        self.bus.declare_alive(self.name)
        tracker = FlagStateTracker(self.params)
        while not stop.is_set():
            beat(self.name, f"{self.published} states")
            msg = lines.recv(timeout_s=0.1)
            self._read_speed()
            if msg is None or len(msg.t_s) == 0:
                continue
            try:
                states = tracker.push(msg.batch())
            except ValueError as exc:  # centrelines of another shape (another tracker set-up): start again
                self._problems.add("centreline messages that cannot be used", exc)
                tracker = FlagStateTracker(self.params)
                continue
            for state in states:
                publisher.put(self._message(state, msg))
                self.published += 1
            self._problems.flush()

    def _read_speed(self) -> None:
        """Keep the tunnel's newest readback (-1.0: not known)."""
        while self._tunnel is not None and (state := self._tunnel.recv(timeout_s=0)) is not None:
            self._speed_mps = state.speed_mps if math.isfinite(state.speed_mps) and state.speed_mps >= 0 else -1.0

    def _message(self, state: CycleState, msg: CentrelineMessage) -> FlagState:
        source_ns = msg.source_ns[state.index] if state.index < len(msg.source_ns) else 0
        return flag_state_message(
            state, self.camera_id, self.published, self._speed_mps, msg.units, int(source_ns), time.time_ns()
        )


def flag_state_message(
    state: CycleState, source: str, seq: int, speed_mps: float, units: str, source_ns: int, published_ns: int
) -> FlagState:
    """The wire message of a core state (numbers not known as ``-1.0``)."""
    return FlagState(
        source=source,
        seq=seq,
        t_s=state.t_s,
        tip_x=state.tip_x,
        tip_y=state.tip_y,
        tip_lateral_over_l=state.tip_lateral_over_l,
        flapping=state.flapping,
        amplitude_over_l=_known(state.amplitude_over_l),
        frequency_hz=_known(state.frequency_hz),
        phase_rad=_known(state.phase_rad),
        twi=_known(state.twi),
        lost_fraction=_known(state.lost_fraction),
        stale_fraction=_known(state.stale_fraction),
        speed_mps=_known(speed_mps),
        cycle_start_s=state.cycle_start_s,
        cycle_end_s=state.cycle_end_s,
        updates=state.updates,
        completes_cycle=state.completes_cycle,
        units=units,
        source_ns=source_ns,
        published_ns=published_ns,
    )


def _known(value: float) -> float:
    """``value``, or -1.0 when it is not a finite number (the messages' "not known")."""
    return float(value) if np.isfinite(value) else -1.0
