"""The wire schema: every key expression (:mod:`.keys`) and message type (:mod:`.messages`) on the bus, with a
versioned encoding (:mod:`.codec`). It knows nothing of YAML or of the transport."""

from flagtrack.daemon.schema.codec import MAGIC, READABLE_VERSIONS, VERSION, decode, encode
from flagtrack.daemon.schema.keys import Keys
from flagtrack.daemon.schema.messages import (
    MESSAGE_TYPES,
    CameraStatus,
    CentrelineMessage,
    EventPacket,
    EventRate,
    FlagState,
    MessageType,
    RecorderCommand,
    RecorderStatus,
    SensorSamples,
    SpeedReply,
    SpeedRequest,
    SupervisorState,
    TrackerStatus,
    TunnelCommand,
    TunnelState,
)

__all__ = [
    "MAGIC",
    "MESSAGE_TYPES",
    "READABLE_VERSIONS",
    "VERSION",
    "CameraStatus",
    "CentrelineMessage",
    "EventPacket",
    "EventRate",
    "FlagState",
    "Keys",
    "MessageType",
    "RecorderCommand",
    "RecorderStatus",
    "SensorSamples",
    "SpeedReply",
    "SpeedRequest",
    "SupervisorState",
    "TrackerStatus",
    "TunnelCommand",
    "TunnelState",
    "decode",
    "encode",
]
