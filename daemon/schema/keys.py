"""Every key expression on the bus, under one namespace (the messages are :mod:`.messages`')."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Keys:
    """Key expressions under one namespace (lowercase slash-separated words, default ``flagtrack/<rig>``)."""

    namespace: str = "flagtrack/default"

    def camera_events(self, camera_id: str) -> str:
        """Native event packets of one camera (:class:`EventPacket`)."""
        return f"{self.namespace}/camera/{camera_id}/events"

    def camera_status(self, camera_id: str) -> str:
        """Camera state and settings read back (:class:`CameraStatus`)."""
        return f"{self.namespace}/camera/{camera_id}/status"

    def event_rate(self, camera_id: str) -> str:
        """Event-rate statistics of one camera (:class:`EventRate`)."""
        return f"{self.namespace}/camera/{camera_id}/rate"

    def centrelines(self) -> str:
        """Batched tracker output (:class:`CentrelineMessage`)."""
        return f"{self.namespace}/tracker/centreline"

    def tracker_status(self) -> str:
        """Tracker health (:class:`TrackerStatus`)."""
        return f"{self.namespace}/tracker/status"

    def tunnel_state(self) -> str:
        """Wind-tunnel speed and state (:class:`TunnelState`)."""
        return f"{self.namespace}/tunnel/state"

    def tunnel_command(self) -> str:
        """Commands to the tunnel owner (:class:`TunnelCommand`)."""
        return f"{self.namespace}/tunnel/command"

    def supervisor_state(self) -> str:
        """Flag state, sweep progress (:class:`SupervisorState`)."""
        return f"{self.namespace}/supervisor/state"

    def recorder_command(self) -> str:
        """Start/stop/rotate recordings (:class:`RecorderCommand`)."""
        return f"{self.namespace}/recorder/command"

    def recorder_status(self) -> str:
        """What the recorder is writing (:class:`RecorderStatus`)."""
        return f"{self.namespace}/recorder/status"

    def sensor_samples(self, sensor_id: str) -> str:
        """Point-sensor samples (:class:`SensorSamples`)."""
        return f"{self.namespace}/sensor/{sensor_id}/samples"

    def flag_state(self) -> str:
        """The flag's state cycle by cycle (:class:`FlagState`)."""
        return f"{self.namespace}/flag/state"

    def speed_request(self, identity: str) -> str:
        """Wind-speed requests of one identity to the tunnel's owner (:class:`SpeedRequest`); on a
        secured bus only that identity may publish here, so the key says who asks."""
        return f"{self.namespace}/tunnel/request/{identity}"

    def speed_requests(self) -> str:
        """Every identity's speed requests (what the tunnel's owner subscribes to)."""
        return f"{self.namespace}/tunnel/request/*"

    def speed_reply(self) -> str:
        """The tunnel owner's answers to speed requests (:class:`SpeedReply`, naming the request and who asked)."""
        return f"{self.namespace}/tunnel/reply"

    def alive(self, service: str) -> str:
        """Liveliness token of one service instance."""
        return f"{self.namespace}/alive/{service}"

    def alive_all(self) -> str:
        """Liveliness of every service in the namespace."""
        return f"{self.namespace}/alive/**"
