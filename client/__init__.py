"""``flagtrack.client``: a running rig from a notebook or a script (docs/control.md).

::

    from flagtrack.client import Rig

    with Rig.connect("rig.yaml") as rig:          # where the rig listens (bus.listen) or its router
        for state in rig.states(timeout_s=5):     # FlagState, once per flapping cycle
            print(state.t_s, state.amplitude_over_l, state.frequency_hz)
            if state.amplitude_over_l > 0.3:
                print(rig.request_speed(4.8))     # the supervisor's answer: applied_mps, reason
                break

A number of a :class:`FlagState` that is not known is ``-1.0``.
"""

from flagtrack.client.connect import client_bus, endpoint_bus, rig_bus
from flagtrack.client.rig import NoAnswer, Rig, Watch
from flagtrack.daemon.schema import CentrelineMessage, EventRate, FlagState, SpeedReply, SpeedRequest

__all__ = [
    "CentrelineMessage",
    "EventRate",
    "FlagState",
    "NoAnswer",
    "Rig",
    "SpeedReply",
    "SpeedRequest",
    "Watch",
    "client_bus",
    "endpoint_bus",
    "rig_bus",
]
