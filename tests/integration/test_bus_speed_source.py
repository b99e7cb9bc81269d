"""The wind speed a simulated camera reads in a process without the supervisor: its own setting until
the tunnel's state arrives on the bus, then the tunnel's (real Zenoh sessions on loopback)."""

from __future__ import annotations

import math

from flagtrack.daemon.rig.camera import BusSpeedSource
from flagtrack.daemon.schema import TunnelState
from flagtrack.daemon.transport import Bus, BusConfig
from tests.fakes.helpers import wait_subscribed
from tests.integration.test_transport import free_port, wait_for


def test_own_speed_until_the_tunnel_state_arrives() -> None:
    """`flagtrack up` beside `flagtrack tunnel set` (nobody publishes the tunnel's state): the twin
    read 0 m/s, so the flag never flapped and `flagtrack geometry` found no flag in its recording."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/speed", listen=(endpoint,))) as camera_side,
        Bus(BusConfig(namespace="flagtrack/speed", connect=(endpoint,))) as supervisor_side,
    ):
        speed = BusSpeedSource(camera_side, own_mps=6.0)
        assert speed() == 6.0  # (and it subscribes)
        wait_subscribed(supervisor_side, supervisor_side.keys.tunnel_state())
        publisher = supervisor_side.publisher(supervisor_side.keys.tunnel_state())
        publisher.put(TunnelState(2.5, 2.5, "steady", t_wall_s=math.nan))
        assert wait_for(lambda: speed() == 2.5)
        publisher.put(TunnelState(0.0, 0.0, "stopped", t_wall_s=math.nan))
        assert wait_for(lambda: speed() == 0.0)  # a published 0 is the tunnel's, not "unknown"
